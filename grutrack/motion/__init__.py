"""Motion module: batched state-space models (CTRA, Bicycle, CA, CV), the batched EKF / KF, and the per-class
motion configuration (Poly-MOT's nuScenes values by default)."""

from grutrack.motion.config import DEFAULT_CONFIG, build_models, class_matrices, load_motion_config, resolve_config_path
from grutrack.motion.kalman import BatchKalmanFilter, RobustUpdate, wrap_yaw_residual
from grutrack.motion.models import CA, CTRA, CV, MODELS, Bicycle, MotionModel, arc_moments, make_model

__all__ = [
    "CA",
    "CTRA",
    "CV",
    "MODELS",
    "Bicycle",
    "MotionModel",
    "arc_moments",
    "make_model",
    "BatchKalmanFilter",
    "RobustUpdate",
    "wrap_yaw_residual",
    "DEFAULT_CONFIG",
    "build_models",
    "class_matrices",
    "load_motion_config",
    "resolve_config_path",
]
