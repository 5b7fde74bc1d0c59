// placeholder: being written (COLMAP sparse model reader/writer)
