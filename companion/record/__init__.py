"""Flight recording (MCAP, a schema per message), its reader and the deterministic replay."""
