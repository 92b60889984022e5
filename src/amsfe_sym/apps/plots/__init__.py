"""Figures, drawn by the applications from finished runs: ``run`` (one run's estimation,
tracking, NEES and control figures; a study's), ``paper`` (the paper's Figs. 4-7 and 12-14
from a controller comparison).  matplotlib is imported only when a figure is drawn.

May import every room before apps, and apps.reproduce (the comparison it draws).
"""
