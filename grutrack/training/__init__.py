"""Training of the GRU-Kalman filter: GT association, EKF pseudo-labels, the loop, checkpoints."""
