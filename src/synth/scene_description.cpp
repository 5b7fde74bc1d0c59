// placeholder (issue 6 generator)
