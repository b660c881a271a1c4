"""Identification: virtual population, parameter-range classifiers, Neural-ODE fit.

Nothing here imports torch at package import time; the fit lives in ``impctl.identify.fit``.
"""
