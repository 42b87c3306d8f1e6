"""imulog.view"""
