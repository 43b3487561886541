"""The rigid-body tier: a JSBSim aircraft's own files compiled to a plan
that advances any number of aircraft of that type together, computing what
JSBSim 1.3 computes (``cosim.rigid.aircraft``: the whole, in FGFDMExec's
order, and the level trim). Its parts: ``functions`` (JSBSim's functions and
tables), ``airframe`` (metrics, mass balance, aerodynamics), ``atmosphere``
(the standard atmosphere, gravity and the Earth's geometry), ``fcs`` (the
systems, autopilot and flight controls), ``propulsion`` (the compiler of
the engines, thrusters and tanks: the turbine and its direct thruster,
with ``piston`` the piston engine and its propeller, ``propulsion_xml``
their shared XML readers; their plan ``propulsion_plan``, engines and
tanks together, its engines ``turbine_plan`` and ``piston_plan``,
``propulsion_base`` what they share), ``body`` (the equations of motion), with
``kernels`` and ``fused`` (numba loops over the aircraft) and ``linalg``
and ``units`` (JSBSim's frames and unit factors). The vehicle class that
flies it is ``fixed_wing_rigid``."""
