"""Official submission formats: one module per format, each validating before it writes atomically."""
