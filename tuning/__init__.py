"""Tuning jobs: analytic DCU baseline, CMA-ES/Optuna, stable-baselines3."""
