"""orchestrator package (in progress)."""
