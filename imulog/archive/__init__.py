"""imulog.archive"""
