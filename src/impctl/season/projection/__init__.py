"""The season model's heat balance as a linear problem and its search (variable projection).

:mod:`.columns` reads the 5R1C balance in demand form as regressors linear in β for given
nonlinear parameters θ; :mod:`.gram` gives the gains' Gram products from their shapes'
structure and :mod:`.normal` the normal equations from them, without forming X;
:mod:`.jacobian` the projected residual's Jacobian; :mod:`.solve` searches θ with β solved
inside; :mod:`.uncertainty` gives the covariance the intervals come from. No torch, no pandas.
"""
