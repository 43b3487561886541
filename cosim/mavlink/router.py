"""Each message an endpoint receives (from the network, or injected by an
in-process client) to the vehicles it addresses, and what they answer.

Our own packets sent back are dropped (``echoes``); a message addressed to
no vehicle (a ground station's HEARTBEAT) is only logged; a system id no
vehicle has, or another component (a camera, a gimbal), is ignored; each is
counted. Every vehicle addressed (target 0: all) logs the message in its
tlog and has it handled (``cosim.mavlink.handlers``: the services); the
replies go out to the peers and the sender, the commands produced leave as
``VehicleCommand``s naming where they came from. A handler's failure is a
bug, not bad input: logged, counted (``handler_errors``) and answered (a
command with COMMAND_ACK FAILED), never raised.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Sequence
from typing import NamedTuple

from cosim.guidance.commands import Command
from cosim.mavlink import adapter as mav
from cosim.mavlink.handlers import Handler
from cosim.mavlink.outbox import Outbox
from cosim.mavlink.outcome import Outcome, command_ack
from cosim.mavlink.vehicle import MavVehicle

log = logging.getLogger(__name__)


class VehicleCommand(NamedTuple):
    """A command for guidance: apply ``command`` to state row ``row``."""

    row: int
    command: Command
    #: what it came from, e.g. ``"COMMAND_INT MAV_CMD_DO_REPOSITION from 255/190"``
    origin: str


def origin(m: mav.Message) -> str:
    """What a command came from: the message (and its MAV_CMD) and its sender."""
    what = m.name
    if m.name in ("COMMAND_LONG", "COMMAND_INT"):
        what += f" {mav.command_name(int(m.fields['command']))}"
    src = "in-process" if not m.raw else f"from {m.src_system}/{m.src_component}"
    return f"{what} {src}"


class Router:
    """Routes the messages of one endpoint to its ``vehicles`` (see the module
    docstring)."""

    def __init__(self, vehicles: Sequence[MavVehicle], handler: Handler, outbox: Outbox,
                 counts: Counter[str]) -> None:
        self.vehicles = vehicles
        self.by_sysid = {v.sysid: v for v in vehicles}
        self.handler = handler
        self.outbox = outbox
        self.counts = counts

    def echo(self, m: mav.Message) -> bool:
        """Whether ``m`` came from the network as one of our vehicles (our own
        packet looped back by the network setup, or sent back by someone)."""
        return bool(m.raw) and m.src_system in self.by_sysid \
            and m.src_component == mav.MAV_COMP_ID_AUTOPILOT1

    def dispatch(self, m: mav.Message, tick: int, commands: list[VehicleCommand],
                 sender: tuple[str, int] | None = None) -> None:
        """Handle ``m`` at ``tick``: replies sent (also to ``sender``), the
        commands it produced appended to ``commands``."""
        if self.echo(m):
            self.counts["echoes"] += 1
            return
        tgt = m.target_system
        if tgt is None:  # not addressed to a vehicle (a ground station's HEARTBEAT, ...)
            self.counts["gcs_heartbeats" if m.name == "HEARTBEAT" else "ignored_messages"] += 1
            self.outbox.log_received(self.outbox.received_bytes(m), tick)
            return
        if tgt == 0:
            targets = list(self.vehicles)
        elif tgt in self.by_sysid:
            targets = [self.by_sysid[tgt]]
        else:
            self.counts["unknown_target_system"] += 1
            return
        comp = m.target_component
        if comp not in (None, mav.MAV_COMP_ID_ALL, mav.MAV_COMP_ID_AUTOPILOT1):
            self.counts["other_component"] += 1  # a camera, gimbal, ...: not ours
            return
        raw = self.outbox.received_bytes(m)
        for v in targets:
            self.outbox.log_received(raw, tick, v.sysid)
            out = self._handle(v, m, tick)
            for name, fields in out.replies:
                try:
                    self.outbox.send(v, name, fields, tick, to=sender)
                except ValueError:  # a reply that does not encode: a bug, never a crash
                    log.exception("mavlink: answering %s for system %d failed", m.name,
                                  v.sysid)
                    self.counts["handler_errors"] += 1
            if out.commands:
                came_from = origin(m)
                commands.extend(VehicleCommand(v.row, c, came_from) for c in out.commands)

    def _handle(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        try:
            return self.handler.handle(v, m, tick)
        except Exception:
            # a bug, not bad input: log it loudly, keep flying, still answer
            log.exception("mavlink: handling %s for system %d failed", m.name, v.sysid)
            self.counts["handler_errors"] += 1
            out = Outcome()
            if m.name in ("COMMAND_LONG", "COMMAND_INT"):
                out.replies.append(command_ack(m, int(m.fields["command"]),
                                               mav.MAV_RESULT_FAILED))
            return out
