"""Task-planning attachments (seed 002, section III-C)."""
