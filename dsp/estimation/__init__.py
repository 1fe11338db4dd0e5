"""Estimation library: linear Kalman, unscented Kalman and alpha-beta(-gamma) filters, each
one source that runs float64 (golden), float32 or fixed point by configuration."""
from .alphabeta import (AlphaBetaFilter, AlphaBetaFormats, AlphaBetaRun, kalata,
                        steady_state_gains, tracking_index)
from .events import EventRegistry
from .kalman import KalmanFilter, KalmanFormats, KalmanRun
from .ukf import UKFRun, UnscentedKalmanFilter
from .ukf_formats import UkfFormats, sigma_weights, weight_problem
from .nonlinear import NonlinearModel
from .models import LinearGaussianModel, white_acceleration, white_jerk

__all__ = ["AlphaBetaFilter", "AlphaBetaFormats", "AlphaBetaRun", "kalata", "steady_state_gains",
           "tracking_index", "EventRegistry", "KalmanFilter", "KalmanFormats", "KalmanRun", "LinearGaussianModel",
           "white_acceleration", "white_jerk", "NonlinearModel", "UKFRun",
           "UnscentedKalmanFilter", "UkfFormats", "sigma_weights", "weight_problem"]
