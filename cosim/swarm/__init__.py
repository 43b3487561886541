"""swarm: consensus behaviours for fixed-wing swarms (docs/physics.md, "Swarm
consensus behaviours").

Owns the ``swarm:`` scenario section (``section``, parsed by ``config``), the
consensus laws (``laws``: centroid, rendezvous, anti-rendezvous, biased
flocking, stall speeds), the controller that turns MAVLink telemetry into
DO_REPOSITION commands (``controller``), the run's separation and phase
metrics (``metrics``), ``swarm.png`` (``plot``), and its two transports:
in-process inside ``cosim run`` (``participant``) and over UDP as ``cosim
swarm --connect`` (``external``).

It sees vehicles only through MAVLink telemetry and commands them only with
MAVLink messages; it must not touch the pool, guidance or setpoints. Only
the metrics read the ground truth (the state array), in-process.
"""
