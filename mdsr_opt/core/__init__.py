"""Infrastructure shared by every stage: argument checks, result formatting, progress, statistics."""
