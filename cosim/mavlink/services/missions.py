"""The mission microservice (ArduPilot's protocol; the on-board state is
``cosim.mavlink.mission``): upload (MISSION_COUNT -> MISSION_REQUEST_INT, or
MISSION_REQUEST once the client answers with float MISSION_ITEMs -> ... ->
MISSION_ACK; retried every simulated second, cancelled after 8 s without
progress), download, clear, MISSION_SET_CURRENT / DO_SET_MISSION_CURRENT.
Item 0 is home.

What the items mean is the vehicle's personality's: which items it flies
(``Personality.mission_items``), which it refuses at upload
(``item_problem``), the command a mission becomes in its mission mode
(``mission_route``, flown by ``Context.fly_mission``) and the guided items
outside the protocol (MISSION_ITEM(_INT) with current=2 or 3,
``guided_item``). Progress is tracked from the state rows
(``update``, once per exchange), which sends MISSION_ITEM_REACHED and
MISSION_CURRENT on a change (and 1 Hz as a stream).
"""

from __future__ import annotations

from cosim.mavlink import adapter as mav
from cosim.mavlink.mission import MAX_ITEMS, UPLOAD_RETRY_S, UPLOAD_TIMEOUT_S, MissionItem, Upload
from cosim.mavlink.services.base import Context, Outcome, Reply, mission_ack, text
from cosim.mavlink.vehicle import MavVehicle
from cosim.vehicles.spec import STATE_INDEX as _S


def _item_request(up: Upload) -> Reply:
    return ("MISSION_REQUEST_INT" if up.use_int else "MISSION_REQUEST", {
        "target_system": up.partner[0], "target_component": up.partner[1],
        "seq": up.next_seq, "mission_type": mav.MAV_MISSION_TYPE_MISSION})


class MissionService:
    """The mission protocol for the vehicles of one endpoint."""

    def __init__(self, ctx: Context) -> None:
        self.ctx = ctx
        self.counts = ctx.counts
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

    # -- upload ----------------------------------------------------------------------
    def _count(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        out = Outcome()
        mtype, count = int(m.fields["mission_type"]), int(m.fields["count"])
        partner = (m.src_system, m.src_component)
        ms = v.mission
        if mtype != mav.MAV_MISSION_TYPE_MISSION:  # no fence or rally points in cosim
            out.replies.append(mission_ack(m, mav.MAV_MISSION_UNSUPPORTED, mission_type=mtype))
            return out
        if ms.upload is not None and ms.upload.partner != partner:
            out.replies.append(mission_ack(m, mav.MAV_MISSION_DENIED))
            return out
        if count - 1 > MAX_ITEMS:
            ms.upload = None
            out.replies.append(mission_ack(m, mav.MAV_MISSION_NO_SPACE))
            return out
        if count <= 1:  # nothing (or home only): an empty mission
            ms.upload = None
            self._replaced(v, [], out)
            out.replies.append(mission_ack(m, mav.MAV_MISSION_ACCEPTED))
            return out
        ms.upload = Upload(partner, count, last_request_tick=tick, last_progress_tick=tick)
        out.replies.append(_item_request(ms.upload))
        return out

    def _item(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        current = int(m.fields["current"])
        if current in (2, 3):  # guided goto / altitude change, outside the protocol
            return v.personality.guided_item(self.ctx, v, m, MissionItem.of(m), current)
        out = Outcome()
        mtype = int(m.fields["mission_type"])
        up = v.mission.upload
        if up is None or up.partner != (m.src_system, m.src_component) \
                or mtype != mav.MAV_MISSION_TYPE_MISSION:
            self.counts["mission_unexpected"] += 1
            out.replies.append(mission_ack(m, mav.MAV_MISSION_ERROR, mission_type=mtype))
            return out
        item = MissionItem.of(m)
        if item.seq != up.next_seq:
            if item.seq == up.next_seq - 1:  # a repeat of the last one: ask again
                out.replies.append(_item_request(up))
            else:  # ArduPilot: say so, keep the upload open (it retries or times out)
                out.replies.append(mission_ack(m, mav.MAV_MISSION_INVALID_SEQUENCE))
            return out
        up.use_int = m.name == "MISSION_ITEM_INT"
        if item.seq > 0:  # item 0 is home: its contents are ignored
            result = item.check(v.personality.mission_items)
            why = "refused"
            if result == mav.MAV_MISSION_ACCEPTED:
                problem = v.personality.item_problem(self.ctx, v, item)
                if problem is not None:
                    result, why = mav.MAV_MISSION_INVALID_PARAM7, problem
            if result != mav.MAV_MISSION_ACCEPTED:
                v.mission.upload = None  # the mission on board is unchanged
                self.counts["mission_upload_errors"] += 1
                out.replies.extend(text(f"Mission item {item.seq}: "
                                        f"{mav.command_name(item.command)} {why}"))
                out.replies.append(mission_ack(m, result))
                return out
            up.received.append(item)
        up.next_seq += 1
        up.last_progress_tick = up.last_request_tick = tick
        if up.next_seq < up.count:
            out.replies.append(_item_request(up))
            return out
        v.mission.upload = None
        self.counts["mission_uploads"] += 1
        self._replaced(v, up.received, out)
        out.replies.append(mission_ack(m, mav.MAV_MISSION_ACCEPTED))
        return out

    def _replaced(self, v: MavVehicle, items: list[MissionItem], out: Outcome) -> None:
        """Store a new mission; a vehicle flying one restarts it from item 1 (or,
        with nothing left to fly, holds where it is in its hold mode)."""
        v.mission.replace(items)
        p = v.personality
        if p.auto_mode is None or v.mode != p.auto_mode:
            return
        if self.ctx.fly_mission(v, 1, out) != mav.MAV_RESULT_ACCEPTED \
                and p.hold_mode is not None:
            p.enter_mode(self.ctx, v, p.hold_mode, 0, out)

    # -- download, clear, acknowledgements ---------------------------------------------
    def _request_list(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        mtype = int(m.fields["mission_type"])
        count = v.mission.count if mtype == mav.MAV_MISSION_TYPE_MISSION else 0
        return Outcome(replies=[("MISSION_COUNT", {
            "target_system": m.src_system, "target_component": m.src_component,
            "count": count, "mission_type": mtype})])

    def _request(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        mtype = int(m.fields["mission_type"])
        item = v.mission.item(int(m.fields["seq"]), v.home) \
            if mtype == mav.MAV_MISSION_TYPE_MISSION else None
        if item is None:
            return Outcome(replies=[mission_ack(m, mav.MAV_MISSION_INVALID_SEQUENCE,
                                                mission_type=mtype)])
        name = "MISSION_ITEM_INT" if m.name == "MISSION_REQUEST_INT" else "MISSION_ITEM"
        return Outcome(replies=[(name, item.fields(
            name == "MISSION_ITEM_INT", (m.src_system, m.src_component),
            item.seq == v.mission.current and item.seq > 0))])

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
        if mtype not in (mav.MAV_MISSION_TYPE_MISSION, mav.MAV_MISSION_TYPE_ALL):
            out.replies.append(mission_ack(m, mav.MAV_MISSION_UNSUPPORTED, mission_type=mtype))
            return out
        v.mission.upload = None
        self._replaced(v, [], out)
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
        on from it. MISSION_CURRENT follows at the end of the exchange."""
        ms = v.mission
        if not 1 <= seq < ms.count:
            out.replies.extend(text(f"Mission item {seq} does not exist"))
            return mav.MAV_RESULT_DENIED
        if v.personality.auto_mode is not None and v.mode == v.personality.auto_mode:
            return self.ctx.fly_mission(v, seq, out)
        ms.stop()
        ms.current = seq
        return mav.MAV_RESULT_ACCEPTED

    def update(self, v: MavVehicle, tick: int) -> list[Reply]:
        """Once per exchange after the messages: upload retries and timeout,
        progress along the mission being flown (MISSION_ITEM_REACHED) and
        MISSION_CURRENT on a change of the current item."""
        ms = v.mission
        out: list[Reply] = []
        up = ms.upload
        if up is not None and tick - up.last_request_tick >= self.retry_ticks:
            if tick - up.last_progress_tick >= self.timeout_ticks:
                ms.upload = None
                self.counts["mission_upload_timeouts"] += 1
                out.append(("MISSION_ACK", {
                    "target_system": up.partner[0], "target_component": up.partner[1],
                    "type": mav.MAV_MISSION_OPERATION_CANCELLED,
                    "mission_type": mav.MAV_MISSION_TYPE_MISSION}))
            else:
                up.last_request_tick = tick
                self.counts["mission_rerequests"] += 1
                out.append(_item_request(up))
        if v.mode == v.personality.auto_mode and v.row_values is not None:
            ms.track(v.row_values, _S)
        elif ms.route:
            ms.stop()  # left the mission mode: the current item stays, to resume from
        for seq in ms.reached:
            self.counts["mission_items_reached"] += 1
            out.append(("MISSION_ITEM_REACHED", {"seq": seq}))
        ms.reached.clear()
        if ms.reported_current != ms.current and v.period.get("MISSION_CURRENT") is not None:
            out.append(("MISSION_CURRENT", v.fields("MISSION_CURRENT", tick)))
        return out
