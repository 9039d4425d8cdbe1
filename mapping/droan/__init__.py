"""DROAN (thesis 4.4): C-space expansion of disparity images, confidence costs, a pose graph."""
