"""Incoming MAVLink messages -> replies, vehicle state changes and commands,
one module per microservice:

- ``commands``: COMMAND_LONG / COMMAND_INT / SET_MODE (exactly one COMMAND_ACK)
- ``missions``: the mission protocol and mission progress
- ``parameters``: PARAM_* (and FTP, always refused)
- ``targets``: SET_POSITION_TARGET_* (offboard control)

Heartbeat and telemetry are the vehicle's (``cosim.mavlink.vehicle``) and
are streamed by the endpoint. What a command, a mode, a mission item or a
parameter *does* is the vehicle's personality's
(``cosim.mavlink.personality``), supplied by its class. Every command ends as
a mapping in the vocabulary a scenario schedule holds, parsed by
``parse_command`` (``cosim.mavlink.outcome.vocab``) and checked by the
class's safety rule (``base.Context.unsafe``): one command path.
``cosim.mavlink.handlers.Handler`` routes each message to its service; no
service touches sockets: each returns an ``Outcome`` (replies to send,
commands for guidance; ``cosim.mavlink.outcome``).
"""
