"""spslidar: the pseudo-random spread-spectrum single-pixel photon-counting ToF lidar."""

__version__ = "0.1.0"
