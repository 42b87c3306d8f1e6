"""imulog.process"""
