"""The companion process: configuration, vehicle link, camera ingest, mission, main loop, CLI."""
