"""Training of the wire CNN (thesis 2.3): synthetic images, backgrounds, real photos, the loop."""
