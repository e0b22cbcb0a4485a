"""Physics of rain: pure functions, SI units inside (metres, seconds, m^-3).

Modules: ``drops`` (size distributions, fall velocity, shape, Eq. 28 and DSD
moments), ``camera`` (projection, blur circle, depth of field), ``streaks``
(Eqs. 15-18, 29), ``optics`` (Eqs. 5-14), ``visibility`` (Eqs. 20-27).
"""
