"""The scenario's ``swarm:`` section -> a frozen ``SwarmSpec``.

::

    swarm:
      rate_hz: 1                 # controller rate (default 1 Hz)
      separation_warn_m: 50      # event when the closest pair gets nearer (3-D)
      stall_margin: 1.2          # speed floor: margin x stall speed at the bank limit
      groups:
        - name: blue
          vehicles: "uav*"       # 'all', an id, a pattern or a list of them
          layer_spacing_m: 30    # optional: hold layer altitudes (see below)
          phases:
            - {behaviour: anti_rendezvous, mu: -0.5, k_s: 0.05, radius_m: 2000,
               timeout_s: 300}
            - {behaviour: flocking, mu: 0.5, k_s: 0.05, duration_s: 120,
               q: {bearing_deg: 45, distance_m: 1500}}
            - {behaviour: rendezvous, mu: 1, k_s: 0.03, radius_m: 300}

Behaviours and their ends: ``rendezvous`` (0 < mu <= 1) converges when every
vehicle is within ``radius_m`` of the group centroid; ``anti_rendezvous``
(mu < 0) when every vehicle is at least ``radius_m`` from it; ``flocking``
(0 < mu <= 1, bias ``q`` as ``bearing_deg`` + ``distance_m`` or ``north_m``
+ ``east_m``) runs for ``duration_s``. Any phase may have ``timeout_s``: it
then ends with reason ``timeout``. Defaults: mu 1 / -1 / 0.5, k_s 0.02 1/s.

Altitudes: without ``layer_spacing_m`` every vehicle holds its start
altitude; with it, the group's vehicles (in scenario order) hold
``lowest start altitude + rank * layer_spacing_m``.

``stall_margin`` (>= 1, default 1.2 like the autopilot's stall protection)
sets the loiter floor of every commanded speed (see
``cosim.swarm.controller``); 1.0 keeps only the bare stall speeds.

``rate_hz`` must give a whole number of exchanges per controller step (it
divides the physics rate and its period is a multiple of the exchange
period). Parsing reports every problem (file:line: path: message) through
``SectionContext`` and never raises for bad input.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from cosim.core.section import SectionContext
from cosim.mavlink.scenario import mavlink_rows
from cosim.swarm import laws
from cosim.vehicles import get_class

P = tuple[Any, ...]
_NAME = re.compile(r"^[A-Za-z0-9_.\-]+$")

BEHAVIOURS = ("rendezvous", "anti_rendezvous", "flocking")
DEFAULT_MU = {"rendezvous": 1.0, "anti_rendezvous": -1.0, "flocking": 0.5}
DEFAULT_K_S = 0.02  # 1/s
DEFAULT_RATE_HZ = 1.0
DEFAULT_SEPARATION_WARN_M = 50.0
DEFAULT_STALL_MARGIN = 1.2


@dataclass(frozen=True)
class Phase:
    behaviour: str
    mu: float
    k_s: float  # 1/s
    radius_m: float | None  # convergence radius R (rendezvous, anti_rendezvous)
    q_ne_m: tuple[float, float] | None  # flocking bias (north, east)
    duration_s: float | None  # flocking length
    timeout_s: float | None


@dataclass(frozen=True)
class SwarmGroup:
    name: str
    rows: tuple[int, ...]  # vehicle rows in scenario order
    phases: tuple[Phase, ...]
    layer_spacing_m: float | None


@dataclass(frozen=True)
class SwarmSpec:
    groups: tuple[SwarmGroup, ...]
    rate_hz: float
    every_ticks: int  # physics ticks per controller step
    separation_warn_m: float
    stall_margin: float = DEFAULT_STALL_MARGIN

    @property
    def rows(self) -> tuple[int, ...]:
        """Every commanded vehicle row, sorted."""
        return tuple(sorted(r for g in self.groups for r in g.rows))


def _phase(info: SectionContext, d: Any, p: P) -> Phase | None:
    r = info.reader(d, p, ("behaviour", "mu", "k_s", "radius_m", "q", "duration_s",
                           "timeout_s"))
    beh = r.string("behaviour", choices=BEHAVIOURS)
    if beh is None:
        return None
    mu = r.num("mu", DEFAULT_MU[beh])
    k_s = r.num("k_s", DEFAULT_K_S, lo=0, lo_open=True)
    ok = mu is not None and k_s is not None
    if mu is not None:
        if beh == "anti_rendezvous" and not mu < 0:
            info.err(p + ("mu",), f"anti_rendezvous needs mu < 0 (goals away from the "
                                  f"centroid), got {mu:g}")
            ok = False
        elif beh != "anti_rendezvous" and not 0 < mu <= 1:
            info.err(p + ("mu",), f"{beh} needs 0 < mu <= 1 (mu > 1 aims past the centroid, "
                                  f"mu <= 0 away from it), got {mu:g}")
            ok = False
    radius = duration = None
    q = None
    if beh == "flocking":
        if r.has("radius_m"):
            info.err(p + ("radius_m",), "flocking ends after duration_s, not at a radius")
            ok = False
        duration = r.num("duration_s", lo=0, lo_open=True)
        ok = ok and duration is not None
        if not r.has("q"):
            info.err(p, "flocking needs q: {bearing_deg, distance_m} or {north_m, east_m}")
            ok = False
        else:
            qr = info.reader(r.d["q"], p + ("q",), ("bearing_deg", "distance_m", "north_m",
                                                     "east_m"))
            polar = qr.has("bearing_deg") or qr.has("distance_m")
            cart = qr.has("north_m") or qr.has("east_m")
            if polar and cart:
                info.err(p + ("q",), "give q as bearing_deg + distance_m or as north_m + "
                                     "east_m, not both")
                ok = False
            elif polar:
                b = qr.num("bearing_deg", lo=-360, hi=360)
                dist = qr.num("distance_m", lo=0, lo_open=True)
                if b is not None and dist is not None:
                    qn, qe = laws.q_vector_ne_m(b, dist).tolist()
                    q = (qn, qe)
            else:
                n, e = qr.num("north_m", 0.0), qr.num("east_m", 0.0)
                if n is not None and e is not None:
                    if n == 0 and e == 0:
                        info.err(p + ("q",), "q is zero: give a direction to flock in")
                    else:
                        q = (n, e)
            ok = ok and q is not None
    else:
        for key in ("q", "duration_s"):
            if r.has(key):
                info.err(p + (key,), f"{key} is for flocking; {beh} ends at radius_m "
                                     f"(or timeout_s)")
                ok = False
        radius = r.num("radius_m", lo=0, lo_open=True)
        ok = ok and radius is not None
    timeout = r.num("timeout_s", None, lo=0, lo_open=True)
    if not ok or mu is None or k_s is None:
        return None
    return Phase(beh, mu, k_s, radius, q, duration, timeout)


def _rate(info: SectionContext, r: Any, path: P) -> tuple[float, int]:
    rate = r.num("rate_hz", DEFAULT_RATE_HZ, lo=0, lo_open=True)
    if rate is None:
        return DEFAULT_RATE_HZ, 1
    ph, k = info.rates.physics_hz, info.rates.control_every
    every = ph / rate
    if abs(every - round(every)) > 1e-9 or round(every) < 1:
        info.err(path + ("rate_hz",), f"rate_hz {rate:g} must divide physics_hz {ph:g} (a "
                                      f"whole number of physics ticks per controller step)")
        return rate, 1
    if round(every) % k:
        info.err(path + ("rate_hz",), f"rate_hz {rate:g} gives {round(every)} physics ticks "
                                      f"per step, not a multiple of the {k} ticks per exchange "
                                      f"(control_hz {info.rates.control_hz:g}); try a rate "
                                      f"dividing control_hz")
    return rate, int(round(every))


def parse_swarm(info: SectionContext, node: Any, path: P) -> SwarmSpec | None:
    """The ``SECTIONS`` parser of ``swarm:`` (see the module docstring)."""
    r = info.reader(node, path, ("rate_hz", "separation_warn_m", "stall_margin", "groups"))
    rate, every = _rate(info, r, path)
    from cosim.mavlink.vehicle import DEFAULT_RATES_HZ

    rates = (info.mavlink or {}).get("rates_hz", {})
    for msg in ("GLOBAL_POSITION_INT", "ATTITUDE"):  # what the controller reads
        if rates.get(msg, DEFAULT_RATES_HZ.get(msg, 0.0)) <= 0:
            info.err(("mavlink", "rates_hz", msg), f"the swarm controller reads {msg}: its "
                                                   "rate must be above 0")
    warn = r.num("separation_warn_m", DEFAULT_SEPARATION_WARN_M, lo=0)
    margin = r.num("stall_margin", DEFAULT_STALL_MARGIN, lo=1.0, hi=3.0)
    groups_node = r.d.get("groups")
    if not isinstance(groups_node, list) or not groups_node:
        info.err(path + (("groups",) if r.has("groups") else ()),
                 "expected groups: a non-empty list of {name, vehicles, phases}")
        return None
    groups: list[SwarmGroup] = []
    owner: dict[int, str] = {}
    names: set[str] = set()
    for gi, gd in enumerate(groups_node):
        gp = path + ("groups", gi)
        g = info.reader(gd, gp, ("name", "vehicles", "phases", "layer_spacing_m"))
        name = g.string("name", f"group{gi}", pattern=_NAME)
        if name is not None and name in names:
            info.err(gp + ("name",), f"duplicate group name {name!r}")
        names.add(name or "")
        rows = info.select(g.d.get("vehicles", "all"), gp + ("vehicles",))
        for row in rows:
            v = info.vehicles[row]
            if row in owner:
                info.err(gp + ("vehicles",), f"vehicle {v.id!r} is already in group "
                                             f"{owner[row]!r}; a vehicle flies in one group")
            owner.setdefault(row, name or "")
            vc = get_class(v.vehicle_class)
            problem = vc.swarm_problem(v)
            if problem is not None:
                info.err(gp + ("vehicles",), problem)
            agl, floor = v.alt_msl_m - v.terrain_alt_m, vc.min_alt_agl_m(v.profile)
            if agl < floor:  # the group holds its start altitudes (or layers above them)
                info.err(gp + ("vehicles",), f"vehicle {v.id!r} starts {agl:g} m above the "
                                             f"ground: the swarm holds that altitude, and "
                                             f"commands below {floor:g} m above the ground "
                                             f"are refused")
        if len(rows) == 1:
            info.err(gp + ("vehicles",), "a swarm group needs at least 2 vehicles")
        spacing = g.num("layer_spacing_m", None, lo=0, lo_open=True)
        phases_node = g.d.get("phases")
        if not isinstance(phases_node, list) or not phases_node:
            info.err(gp + (("phases",) if g.has("phases") else ()),
                     "expected phases: a non-empty list of behaviours")
            continue
        phases = [_phase(info, pd, gp + ("phases", pi)) for pi, pd in enumerate(phases_node)]
        good = [ph for ph in phases if ph is not None]
        if name is None or len(good) != len(phases) or len(rows) < 2:
            continue
        groups.append(SwarmGroup(name, tuple(rows), tuple(good), spacing))
    on_mav = mavlink_rows(info.mavlink, info.ids)
    if on_mav is not None:  # the swarm commands through MAVLink
        on = set(on_mav)
        off = [info.vehicles[r].id for g in groups for r in g.rows if r not in on]
        if off:
            info.err(path, f"vehicles {', '.join(off[:5])}{' ...' if len(off) > 5 else ''} "
                           f"are not in mavlink.vehicles, and the swarm flies its vehicles "
                           f"through MAVLink")
    if warn is None or margin is None:
        return None
    return SwarmSpec(tuple(groups), rate, every, warn, margin)
