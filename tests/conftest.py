"""Shared fixtures; matplotlib renders off-screen in every test."""

import matplotlib

matplotlib.use("Agg")
