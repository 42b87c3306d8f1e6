"""imulog.steps"""
