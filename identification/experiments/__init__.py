"""Experiments on top of the method: the paper's reproduction, studies, truth comparisons.

These modules may use the ground-truth simulator and the true coefficients; the method
(``identification.data``, ``features``, ``libraries``, ``fit``, ``selection``, ``model``)
never does.
"""
