"""Figures the jobs draw: the measured release curve and a sweep's contact sheet."""
