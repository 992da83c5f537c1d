"""grutrack: 3D multi-object tracking with a semi-supervised GRU-Kalman filter (GRUTrack), reproducibility toolkit."""

__version__ = "0.1.0"
