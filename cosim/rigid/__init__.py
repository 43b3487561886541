"""The rigid-body tier: JSBSim aircraft files compiled to vectorised kernels
(``cosim.rigid.functions``: the aerodynamic functions and tables;
``cosim.rigid.atmosphere``: the standard atmosphere, gravity and the Earth's
geometry)."""
