"""Navigation across planar regions (seed 000, section V)."""
