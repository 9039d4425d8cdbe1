"""Wire segmentation (thesis ch. 2): pure, synchronous; arrays in, arrays out."""
