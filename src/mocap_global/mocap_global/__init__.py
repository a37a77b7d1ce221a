"""GMR: world-frame global motion from the local pose sequence with a bidirectional GRU."""
