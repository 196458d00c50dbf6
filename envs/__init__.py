"""Gymnasium environments for tuning xy-twin machines."""
