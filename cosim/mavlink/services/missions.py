"""The mission microservice (ArduPilot's protocol; the on-board state and
the flying of missions are ``cosim.mavlink.mission``): upload
(MISSION_COUNT -> MISSION_REQUEST_INT, or MISSION_REQUEST once the client
answers with float MISSION_ITEMs -> ... -> MISSION_ACK; retried every
simulated second, cancelled after 8 s without progress), download, clear,
MISSION_SET_CURRENT / DO_SET_MISSION_CURRENT, for the three lists: the
mission (item 0 is home), the fence and the rally points.

What the items mean is the vehicle's personality's: which items it flies
(``Personality.mission_items``: others are stored and skipped in flight),
which it refuses as unsafe (``item_problem``, likewise), the command each
navigation item becomes (``nav_vocab``) and the guided items outside the
protocol (MISSION_ITEM(_INT) with current=2 or 3, ``guided_item``).

``update`` runs once per exchange, before the step: the upload's retries,
the fence (a breach switches an armed vehicle to its RTL mode, with a
``fence_breach`` event), the mission being flown (its commands, and
MISSION_ITEM_REACHED), and MISSION_CURRENT on a change (and 1 Hz as a
stream).
"""

from __future__ import annotations

from cosim.core.state import STATE_INDEX as _S
from cosim.mavlink import adapter as mav
from cosim.mavlink import fence
from cosim.mavlink.mission import (
    LIST_RULES,
    MAX_ITEMS,
    UPLOAD_RETRY_S,
    UPLOAD_TIMEOUT_S,
    MissionItem,
    Upload,
    result_name,
)
from cosim.mavlink.mission_runner import MissionRunner
from cosim.mavlink.outcome import Outcome, Reply, mission_ack, text
from cosim.mavlink.services.base import Context
from cosim.mavlink.vehicle import MavVehicle

_MISSION = mav.MAV_MISSION_TYPE_MISSION


def _item_request(up: Upload) -> Reply:
    return ("MISSION_REQUEST_INT" if up.use_int else "MISSION_REQUEST", {
        "target_system": up.partner[0], "target_component": up.partner[1],
        "seq": up.next_seq, "mission_type": up.mission_type})


class MissionService:
    """The mission protocol for the vehicles of one endpoint."""

    def __init__(self, ctx: Context) -> None:
        self.ctx = ctx
        self.counts = ctx.counts
        self.runner = MissionRunner(ctx)
        self.messages = {
            "MISSION_COUNT": self._count,
            "MISSION_ITEM_INT": self._item,
            "MISSION_ITEM": self._item,
            "MISSION_REQUEST_LIST": self._request_list,
            "MISSION_REQUEST_INT": self._request,
            "MISSION_REQUEST": self._request,
            "MISSION_ACK": self._ack_in,
            "MISSION_CLEAR_ALL": self._clear,
            "MISSION_SET_CURRENT": self._set_current_msg,
        }
        self.retry_ticks = max(1, round(UPLOAD_RETRY_S * ctx.physics_hz))
        self.timeout_ticks = max(1, round(UPLOAD_TIMEOUT_S * ctx.physics_hz))

    @staticmethod
    def _lists(v: MavVehicle) -> bool:
        """Whether ``v`` keeps missions (and fence and rally lists) at all."""
        return v.personality.auto_mode is not None and v.personality.autopilot

    # -- upload ----------------------------------------------------------------------
    def _count(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        out = Outcome()
        mtype, count = int(m.fields["mission_type"]), int(m.fields["count"])
        partner = (m.src_system, m.src_component)
        ms = v.mission
        if mtype not in LIST_RULES or not self._lists(v):  # it flies no missions
            out.replies.append(mission_ack(m, mav.MAV_MISSION_UNSUPPORTED, mission_type=mtype))
            return out
        if ms.upload is not None and ms.upload.partner != partner:
            out.replies.append(mission_ack(m, mav.MAV_MISSION_DENIED, mission_type=mtype))
            return out
        home = 1 if mtype == _MISSION else 0
        if count - home > LIST_RULES[mtype][1]:
            ms.upload = None
            out.replies.append(mission_ack(m, mav.MAV_MISSION_NO_SPACE, mission_type=mtype))
            return out
        if count <= home:  # nothing (or home only): an empty list
            ms.upload = None
            self._replaced(v, [], {}, mtype, out)
            out.replies.append(mission_ack(m, mav.MAV_MISSION_ACCEPTED, mission_type=mtype))
            return out
        ms.upload = Upload(partner, count, last_request_tick=tick, last_progress_tick=tick,
                           mission_type=mtype)
        out.replies.append(_item_request(ms.upload))
        return out

    def _item(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        current = int(m.fields["current"])
        mtype = int(m.fields["mission_type"])
        if current in (2, 3) and mtype == _MISSION:  # guided goto / altitude change
            return v.personality.guided_item(self.ctx, v, m, MissionItem.of(m), current)
        out = Outcome()
        up = v.mission.upload
        if up is None or up.partner != (m.src_system, m.src_component) \
                or mtype != up.mission_type:
            self.counts["mission_unexpected"] += 1
            out.replies.append(mission_ack(m, mav.MAV_MISSION_ERROR, mission_type=mtype))
            return out
        item = MissionItem.of(m)
        if item.seq != up.next_seq:
            if item.seq == up.next_seq - 1:  # a repeat of the last one: ask again
                out.replies.append(_item_request(up))
            else:  # ArduPilot: say so, keep the upload open (it retries or times out)
                out.replies.append(mission_ack(m, mav.MAV_MISSION_INVALID_SEQUENCE,
                                               mission_type=mtype))
            return out
        up.use_int = m.name == "MISSION_ITEM_INT"
        if item.seq > 0 or mtype != _MISSION:  # mission item 0 is home: ignored
            result = item.check(up.count)
            if result != mav.MAV_MISSION_ACCEPTED:  # malformed: the upload ends
                v.mission.upload = None  # the plan on board is unchanged
                self.counts["mission_upload_errors"] += 1
                out.replies.extend(text(f"Mission item {item.seq}: "
                                        f"{mav.command_name(item.command)} refused: "
                                        f"{result_name(result)}"))
                out.replies.append(mission_ack(m, result, mission_type=mtype))
                return out
            if mtype == _MISSION:
                self._flyable(v, item, up, out)
            up.received.append(item)
        up.next_seq += 1
        up.last_progress_tick = up.last_request_tick = tick
        if up.next_seq < up.count:
            out.replies.append(_item_request(up))
            return out
        v.mission.upload = None
        self.counts["mission_uploads"] += 1
        self._replaced(v, up.received, dict(up.refused), mtype, out)
        out.replies.append(mission_ack(m, mav.MAV_MISSION_ACCEPTED, mission_type=mtype))
        return out

    def _flyable(self, v: MavVehicle, item: MissionItem, up: Upload, out: Outcome) -> None:
        """A well-formed item this vehicle cannot fly: kept, reported, skipped
        in flight (the rest of the plan is flown as uploaded)."""
        p = v.personality
        if item.command not in p.mission_items:
            result, why = mav.MAV_MISSION_UNSUPPORTED, "not supported by this vehicle"
        else:
            problem = p.item_problem(self.ctx, v, item)
            if problem is None:
                return
            result, why = mav.MAV_MISSION_INVALID_PARAM7, problem
        up.refused.append((item.seq, result))
        self.counts["mission_items_refused"] += 1
        out.replies.extend(text(f"Mission item {item.seq}: {mav.command_name(item.command)} "
                                f"{why} ({result_name(result)}); skipped"))

    def _replaced(self, v: MavVehicle, items: list[MissionItem], refused: dict[int, int],
                  mtype: int, out: Outcome) -> None:
        """Store a new list; a vehicle flying the mission restarts a new one
        from item 1 (or, with nothing left to fly, holds where it is)."""
        v.mission.replace(items, refused, mtype)
        p = v.personality
        if mtype != _MISSION or p.auto_mode is None or v.mode != p.auto_mode:
            return
        if self.ctx.fly_mission(v, 1, out) != mav.MAV_RESULT_ACCEPTED \
                and p.hold_mode is not None:
            p.enter_mode(self.ctx, v, p.hold_mode, 0, out)

    def load(self, v: MavVehicle, items: list[MissionItem], fly: bool) -> Outcome:
        """A mission put on board from inside cosim (a plan loaded before the
        flight): each item checked as an upload checks it (a malformed one is
        the caller's error: ``ValueError``), stored, and with ``fly`` flown
        from item 1 in the vehicle's mission mode."""
        out = Outcome()
        if not self._lists(v):
            out.replies.extend(text("Mission: this vehicle flies no missions"))
            return out
        if len(items) > MAX_ITEMS:
            raise ValueError(f"a mission of {len(items)} items; a vehicle holds at most "
                             f"{MAX_ITEMS}")
        up = Upload((0, 0), len(items) + 1)
        for k, item in enumerate(items, start=1):
            if item.seq != k:
                raise ValueError(f"mission item {k} has seq {item.seq}")
            result = item.check(up.count)
            if result != mav.MAV_MISSION_ACCEPTED:
                raise ValueError(f"mission item {k}: {mav.command_name(item.command)}: "
                                 f"{result_name(result)}")
            self._flyable(v, item, up, out)
        self.counts["missions_loaded"] += 1
        self._replaced(v, list(items), dict(up.refused), _MISSION, out)
        p = v.personality
        if fly and v.mode != p.auto_mode \
                and self.ctx.fly_mission(v, 1, out) != mav.MAV_RESULT_ACCEPTED:
            self.counts["missions_not_started"] += 1
        return out

    # -- download, clear, acknowledgements ---------------------------------------------
    def _request_list(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        mtype = int(m.fields["mission_type"])
        count = v.mission.count_of(mtype) if mtype in LIST_RULES else 0
        return Outcome(replies=[("MISSION_COUNT", {
            "target_system": m.src_system, "target_component": m.src_component,
            "count": count, "mission_type": mtype})])

    def _request(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        mtype = int(m.fields["mission_type"])
        item = v.mission.item(int(m.fields["seq"]), v.home, mtype) \
            if mtype in LIST_RULES else None
        if item is None:
            return Outcome(replies=[mission_ack(m, mav.MAV_MISSION_INVALID_SEQUENCE,
                                                mission_type=mtype)])
        name = "MISSION_ITEM_INT" if m.name == "MISSION_REQUEST_INT" else "MISSION_ITEM"
        return Outcome(replies=[(name, item.fields(
            name == "MISSION_ITEM_INT", (m.src_system, m.src_component),
            mtype == _MISSION and item.seq == v.mission.current and item.seq > 0))])

    def _ack_in(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        up = v.mission.upload
        if up is not None and up.partner == (m.src_system, m.src_component) \
                and int(m.fields["type"]) != mav.MAV_MISSION_ACCEPTED:
            v.mission.upload = None  # the client cancelled its upload
            self.counts["mission_upload_errors"] += 1
        elif int(m.fields["type"]) == mav.MAV_MISSION_ACCEPTED:
            self.counts["mission_downloads"] += 1
        return Outcome()

    def _clear(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        out = Outcome()
        mtype = int(m.fields["mission_type"])
        if mtype == mav.MAV_MISSION_TYPE_ALL:
            types = list(LIST_RULES)
        elif mtype in LIST_RULES:
            types = [mtype]
        else:
            out.replies.append(mission_ack(m, mav.MAV_MISSION_UNSUPPORTED, mission_type=mtype))
            return out
        v.mission.upload = None
        for t in types:
            self._replaced(v, [], {}, t, out)
        out.replies.append(mission_ack(m, mav.MAV_MISSION_ACCEPTED, mission_type=mtype))
        return out

    # -- the current item -----------------------------------------------------------
    def _set_current_msg(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        out = Outcome()
        if self.set_current(v, int(m.fields["seq"]), out) != mav.MAV_RESULT_ACCEPTED:
            self.counts["commands_refused"] += 1
        return out

    def set_current(self, v: MavVehicle, seq: int, out: Outcome) -> int:
        """Make ``seq`` the current item; flying the mission, the vehicle flies
        on from it. MISSION_CURRENT follows in the same exchange."""
        ms = v.mission
        if not 1 <= seq < ms.count:
            out.replies.extend(text(f"Mission item {seq} does not exist"))
            return mav.MAV_RESULT_DENIED
        if v.personality.auto_mode is not None and v.mode == v.personality.auto_mode:
            return self.ctx.fly_mission(v, seq, out)
        ms.stop()
        ms.current = seq
        return mav.MAV_RESULT_ACCEPTED

    def start(self, v: MavVehicle, first: int, out: Outcome) -> int:
        """MISSION_START: fly the mission in the mission mode from item
        ``first`` (0: the current item, or the first)."""
        ms = v.mission
        if first and not 1 <= first < ms.count:
            out.replies.extend(text(f"Mission item {first} does not exist"))
            return mav.MAV_RESULT_DENIED
        r = self.ctx.fly_mission(v, first or ms.current or 1, out)
        return r

    # -- every exchange -------------------------------------------------------------
    def update(self, v: MavVehicle, tick: int) -> Outcome:
        """Once per exchange before the step (see the module docstring)."""
        self.ctx.tick = tick
        ms = v.mission
        out = Outcome()
        up = ms.upload
        if up is not None and tick - up.last_request_tick >= self.retry_ticks:
            if tick - up.last_progress_tick >= self.timeout_ticks:
                ms.upload = None
                self.counts["mission_upload_timeouts"] += 1
                out.replies.append(("MISSION_ACK", {
                    "target_system": up.partner[0], "target_component": up.partner[1],
                    "type": mav.MAV_MISSION_OPERATION_CANCELLED,
                    "mission_type": up.mission_type}))
            else:
                up.last_request_tick = tick
                self.counts["mission_rerequests"] += 1
                out.replies.append(_item_request(up))
        if ms.fence:
            self._check_fence(v, tick, out)
        p = v.personality
        if v.mode == p.auto_mode and v.row_values is not None:
            self.runner.update(v, tick, out)
        elif ms.nav is not None:
            ms.stop()  # left the mission mode: the current item stays, to resume from
        for seq in ms.reached:
            out.replies.append(("MISSION_ITEM_REACHED", {"seq": seq}))
        ms.reached.clear()
        if ms.reported_current != ms.current and v.period.get("MISSION_CURRENT") is not None:
            out.replies.append(("MISSION_CURRENT", v.fields("MISSION_CURRENT", tick)))
        return out

    def _check_fence(self, v: MavVehicle, tick: int, out: Outcome) -> None:
        """A breach switches an armed vehicle in the air to its RTL mode, once
        per breach (back inside, a later breach counts again)."""
        row = v.row_values
        if row is None:
            return
        lat, lon = float(row[_S["lat_deg"]]), float(row[_S["lon_deg"]])
        why = fence.breach(v.mission.fence, lat, lon)
        ms = v.mission
        if why is None:
            ms.breached = False
            return
        if ms.breached or not v.armed:
            return
        ms.breached = True
        self.counts["fence_breaches"] += 1
        p = v.personality
        out.replies.extend(text(f"Fence breach: {why}", mav.MAV_SEVERITY_CRITICAL))
        action = "none"
        if p.rtl_mode is not None and v.mode != p.rtl_mode:
            if p.enter_mode(self.ctx, v, p.rtl_mode, tick, out) == mav.MAV_RESULT_ACCEPTED:
                action = p.mode_name(p.rtl_mode)
        out.events.append(("fence_breach", {"why": why, "lat_deg": lat, "lon_deg": lon,
                                            "action": action}))
