"""Camera ingest: frames from a camera source (OAK-D, a recording, a simulator) onto the bus."""
