"""Offline: the cclog command, replay, fleet (Dask), tuning, stats, export, plots, the demo."""
