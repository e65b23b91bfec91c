"""Applications: the sinking-plate model run, its command line and its output writers.

The top layer: nothing below imports from here.
"""
