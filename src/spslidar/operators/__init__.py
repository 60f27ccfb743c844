"""Linear operators with adjoints (the A of equations 7 and 18, and image-space transforms)."""

from .base import Identity, LinearOperator, MatrixOperator, dottest, power_norm
from .hadamard import WalshHadamard
from .image import Gradient2D, Wavelet2D

__all__ = [
    "LinearOperator",
    "MatrixOperator",
    "Identity",
    "Gradient2D",
    "Wavelet2D",
    "WalshHadamard",
    "dottest",
    "power_norm",
]
