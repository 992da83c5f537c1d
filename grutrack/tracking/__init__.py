"""Tracking-by-detection: pre-processing, association, lifecycle and the tracker loop."""
