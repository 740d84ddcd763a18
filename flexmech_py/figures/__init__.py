"""Figures (matplotlib, imported when a figure is asked for). Nothing below imports them."""
