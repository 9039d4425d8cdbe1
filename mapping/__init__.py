"""DROAN mapping (thesis 4.4) and catenary reconstruction (ch. 3): pure, synchronous."""
