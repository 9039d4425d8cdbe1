"""Multi-view catenary reconstruction of wires (thesis ch. 3)."""
