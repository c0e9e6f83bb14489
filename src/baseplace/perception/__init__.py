"""Perception for the pointing application (seed 004, section 3.1): RGB-D frames, objects, gestures, selection."""
