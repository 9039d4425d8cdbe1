"""The live view: a flight or a replay in Foxglove, over its WebSocket protocol."""
