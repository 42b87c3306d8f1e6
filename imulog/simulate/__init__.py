"""imulog.simulate"""
