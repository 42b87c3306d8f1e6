"""imulog.batch"""
