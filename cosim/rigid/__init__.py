"""The rigid-body tier: a JSBSim aircraft's own files compiled to a plan
that advances any number of aircraft of that type together, computing what
JSBSim 1.3 computes (``cosim.rigid.aircraft``: the whole, in FGFDMExec's
order, and the level trim). Its parts: ``functions`` (JSBSim's functions and
tables), ``airframe`` (metrics, mass balance, aerodynamics), ``atmosphere``
(the standard atmosphere, gravity and the Earth's geometry), ``fcs`` (the
systems, autopilot and flight controls), ``propulsion`` (turbine engines,
direct thrusters, tanks), ``body`` (the equations of motion), with
``kernels`` and ``fused`` (numba loops over the aircraft) and ``linalg``
and ``units`` (JSBSim's frames and unit factors). The vehicle class that
flies it is ``fixed_wing_rigid``."""
