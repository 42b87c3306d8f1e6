"""imulog: wearable-IMU rehabilitation trials as self-describing MCAP archives."""

__version__ = "0.1.0"
