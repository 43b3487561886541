"""The parameter microservice (PARAM_REQUEST_LIST, PARAM_REQUEST_READ,
PARAM_SET -> PARAM_VALUE) over each vehicle's table, whose definitions its
personality supplies (``Personality.param_defs``); what a parameter does
when set is the personality's too (``param_problem``, ``param_command``).

And MAVLink FTP, answered with a NAK to every request so that ground
stations fall back at once to the parameter and mission protocols.
"""

from __future__ import annotations

import struct

from cosim.guidance.commands import Command
from cosim.mavlink import adapter as mav
from cosim.mavlink.outcome import Outcome, Reply, text, vocab
from cosim.mavlink.services.base import Context
from cosim.mavlink.vehicle import MavVehicle

# MAVLink FTP (https://mavlink.io/en/services/ftp.html)
_FTP_ACK, _FTP_NAK = 128, 129
_FTP_ERR_FAIL, _FTP_ERR_INVALID_SESSION, _FTP_ERR_FILE_NOT_FOUND = 1, 4, 10
_FTP_PATH_OPS = {3, 4, 6, 8, 9, 10, 11, 12, 13, 14}  # list/open/create/remove/.../crc
_FTP_SESSION_OPS = {1, 5, 7, 15}  # terminate, read, write, burst read
_FTP_HEADER = struct.Struct("<HBBBBBBI")


def param_value(v: MavVehicle, index: int) -> Reply:
    """The PARAM_VALUE of ``v``'s parameter number ``index``."""
    p = v.params.defs[index]
    return ("PARAM_VALUE", {"param_id": p.name, "param_value": v.params.values[index],
                            "param_type": p.mav_type, "param_count": len(v.params),
                            "param_index": index})


class ParamService:
    """PARAM_* and FTP for the vehicles of one endpoint."""

    def __init__(self, ctx: Context) -> None:
        self.ctx = ctx
        self.counts = ctx.counts
        self.messages = {"PARAM_REQUEST_LIST": self._list, "PARAM_REQUEST_READ": self._read,
                         "PARAM_SET": self._set, "FILE_TRANSFER_PROTOCOL": self._ftp}

    def value(self, v: MavVehicle, name: str) -> Reply:
        """The PARAM_VALUE of one parameter (to announce a change)."""
        return param_value(v, v.params.index[name])

    def _list(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        return Outcome(replies=[param_value(v, i) for i in range(len(v.params))])

    def _read(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        idx = int(m.fields["param_index"])
        if idx < 0:
            idx = v.params.index.get(str(m.fields["param_id"]).strip("\0 "), -1)
        if not 0 <= idx < len(v.params):
            self.counts["param_unknown"] += 1
            return Outcome()
        return Outcome(replies=[param_value(v, idx)])

    def _set(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        name = str(m.fields["param_id"]).strip("\0 ")
        idx = v.params.index.get(name)
        if idx is None:
            self.counts["param_unknown"] += 1
            return Outcome()
        value = float(m.fields["param_value"])
        out = Outcome()
        problem = v.params.check(name, value) \
            or v.personality.param_problem(self.ctx, v, name, value) or v.params.set(name, value)
        if problem:
            self.counts["param_rejected"] += 1
            out.replies.extend(text(f"{name}: {problem}"))
        else:
            d = v.personality.param_command(v, name)
            if d is not None:
                cmd = vocab(d)
                if isinstance(cmd, Command):
                    out.commands.append(cmd)
        out.replies.append(param_value(v, idx))  # the value now in force
        return out

    def _ftp(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        payload = bytes(int(b) & 0xFF for b in m.fields["payload"])
        if len(payload) < _FTP_HEADER.size:
            return Outcome()
        seq, session, opcode = _FTP_HEADER.unpack_from(payload)[:3]
        if opcode in (_FTP_ACK, _FTP_NAK):  # a response, not a request: never answer
            return Outcome()
        err = (_FTP_ERR_FILE_NOT_FOUND if opcode in _FTP_PATH_OPS else
               _FTP_ERR_INVALID_SESSION if opcode in _FTP_SESSION_OPS else _FTP_ERR_FAIL)
        head = _FTP_HEADER.pack((seq + 1) % 65536, session, _FTP_NAK, 1, opcode, 0, 0, 0)
        body = list(head + bytes([err]))
        self.counts["ftp_naks"] += 1
        return Outcome(replies=[("FILE_TRANSFER_PROTOCOL", {
            "target_network": 0, "target_system": m.src_system,
            "target_component": m.src_component, "payload": body + [0] * (251 - len(body))})])
