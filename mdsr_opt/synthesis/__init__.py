"""From target to robot: routing, the design of strokes (flattened NLP and rivals), verification,
the pipeline, several poses on one layout, gait schedules and fabrication files."""
