// placeholder (distractor masks)
