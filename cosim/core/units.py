"""Units and physical constants, one definition each: conversions to SI
(``FT_TO_M``, ``KT_TO_MPS``, ``LBF_TO_N``) and standard gravity. Names say
what they convert from and to; values are exact where the definition is
(the international foot, knot and pound-force)."""

from __future__ import annotations

#: the international foot (m)
FT_TO_M = 0.3048
M_TO_FT = 1.0 / FT_TO_M
#: the knot: one nautical mile (1852 m) per hour (m/s)
KT_TO_MPS = 1852.0 / 3600.0
#: the pound-force (N)
LBF_TO_N = 4.4482216152605
#: pound (mass) to kilogram
LB_TO_KG = 0.45359237
#: standard gravity (m/s^2)
G_MPS2 = 9.80665
