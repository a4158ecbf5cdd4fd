"""Visualisation: overlay videos, error plots and skeleton contact sheets."""
