"""The flight-control components with state, compiled to vectorised
numpy steps as JSBSim 1.3 computes them: FGPID, FGActuator, FGFilter (the
lag, lead-lag, washout, second-order filters and the integrator) and
FGKinemat. Their state (an integrator, past inputs and outputs, an
actuator's last output) lives in ``props`` under private keys
``_fcs:<component property>:<what>``; see ``cosim.rigid.fcs``.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Callable
from typing import Any

import numpy as np

from cosim.rigid.fcs_components import (
    Build,
    Component,
    Context,
    Props,
    Source,
    attrs,
    is_number,
    kids,
    number,
    one,
    param,
    prop,
    text,
)

_EPS = 2.0 * np.finfo(np.float64).eps


def _pid(el: ET.Element, ctx: Context) -> Component:
    b = Build(el, ctx, {"kp", "ki", "kd", "trigger", "pvdot"})
    kind = el.get("type", "")
    if kind not in ("", "standard"):
        raise ctx.fail(el, f"type={kind!r} is not supported (only 'standard')")
    standard = kind == "standard"
    b.input_count(1, 1)
    zero: Source = lambda p: 0.0  # noqa: E731

    def gain(tag: str) -> tuple[Source, ET.Element | None]:
        e = one(el, tag, ctx)
        if e is None:
            return zero, None
        t = text(e)
        allowed = {"type"} if tag == "ki" else set()
        attrs(e, ctx, allowed)
        if not t or " " in t:
            raise ctx.fail(e, f"expected a number or a property, got {t!r}")
        return param(t, b.reads), e

    kp, _ = gain("kp")
    ki, ki_el = gain("ki")
    kd, _ = gain("kd")
    integ = "none"
    if ki_el is not None:
        integ = ki_el.get("type", "ab2")
        if integ not in ("rect", "trap", "ab2", "ab3"):
            integ = "ab2"  # JSBSim's default for any other type
    tr = one(el, "trigger", ctx)
    trigger = prop(text(tr), b.reads) if tr is not None else None
    pv = one(el, "pvdot", ctx)
    pvdot = prop(text(pv), b.reads) if pv is not None else None
    x, name = b.inputs[0], b.name
    k_tot, k_prev, k_prev2 = b.key("i_out_total"), b.key("input_prev"), b.key("input_prev2")
    b.state.update({k_tot: 0.0, k_prev: 0.0, k_prev2: 0.0})

    def compute(p: Props, dt: float) -> dict[str, Any]:
        u = np.asarray(x(p), dtype=np.float64)
        prev, prev2, total = p[k_prev], p[k_prev2], p[k_tot]
        dval = pvdot(p) if pvdot is not None else (u - prev) / dt
        if integ == "rect":
            delta = u
        elif integ == "trap":
            delta = 0.5 * (u + prev)
        elif integ == "ab2":
            delta = 1.5 * u - 0.5 * prev
        elif integ == "ab3":
            delta = (23.0 * u - 16.0 * prev + 5.0 * prev2) / 12.0
        else:
            delta = np.zeros_like(u)
        if trigger is not None:
            test = trigger(p)
            delta = np.where(np.abs(test) < 0.000001, delta, 0.0)
            reset = test < 0.0
            total = np.where(reset, 0.0, total)
            new_prev2 = np.where(reset, 0.0, prev)
        else:
            new_prev2 = prev
        total = total + ki(p) * dt * delta
        if standard:
            out = kp(p) * (u + total + kd(p) * dval)
        else:
            out = kp(p) * u + total + kd(p) * dval
        return {name: out, k_tot: total, k_prev: u, k_prev2: new_prev2}
    return b.done(compute)


def _actuator(el: ET.Element, ctx: Context) -> Component:
    b = Build(el, ctx, {"lag", "rate_limit", "deadband_width", "hysteresis_width", "bias"})
    b.input_count(1, 1)

    def num(tag: str) -> float:
        e = one(el, tag, ctx)
        return number(e, ctx) if e is not None else 0.0

    lag, dbw, hyw, bias = num("lag"), num("deadband_width"), num("hysteresis_width"), num("bias")
    incr: Source | None = None
    decr: Source | None = None
    for r in el.findall("rate_limit"):
        attrs(r, ctx, {"sense"})
        sense = r.get("sense", "")
        t = text(r)
        if not t or " " in t or list(kids(r)):
            raise ctx.fail(r, f"expected a number or a property, got {t!r}")
        src = param(t, b.reads)
        if sense.startswith("incr"):
            incr = src
        elif sense.startswith("decr"):
            decr = src
        else:
            incr = decr = src
    x, name = b.inputs[0], b.name
    fz, fh, fs = (f"{name}/malfunction/fail_zero", f"{name}/malfunction/fail_hardover",
                  f"{name}/malfunction/fail_stuck")
    sat = f"{name}/saturated"
    b.reads |= {fz, fh, fs}
    k_init, k_prev = b.key("initialized"), b.key("previous_output")
    k_lag_in, k_lag_out = b.key("lag_input"), b.key("lag_output")
    k_rate, k_hyst = b.key("rate_output"), b.key("hysteresis_output")
    b.state.update({k_init: 0.0, k_prev: 0.0, k_lag_in: 0.0, k_lag_out: 0.0,
                    k_rate: 0.0, k_hyst: 0.0})
    clip = b.clip_minmax

    def compute(p: Props, dt: float) -> dict[str, Any]:
        u = np.asarray(x(p), dtype=np.float64)
        inited = p[k_init] != 0.0
        u = np.where(p[fz] != 0.0, 0.0, u)
        if clip is not None:
            u = np.where(p[fh] != 0.0, np.where(u < 0.0, clip[0](p), clip[1](p)), u)
        else:
            u = np.where(p[fh] != 0.0, 0.0, u)
        out = u
        new: dict[str, np.ndarray] = {}
        if lag != 0.0:
            denom = 2.0 + dt * lag
            ca, cb = dt * lag / denom, (2.0 - dt * lag) / denom
            lagged = np.where(inited, ca * (out + p[k_lag_in]) + p[k_lag_out] * cb, out)
            new[k_lag_in], new[k_lag_out] = out, lagged
            out = lagged
        if incr is not None or decr is not None:
            prev_r = p[k_rate]
            delta = out - prev_r
            r_out = out
            if incr is not None:
                lim = incr(p)
                r_out = np.where(delta > dt * lim, prev_r + lim * dt, r_out)
            if decr is not None:
                lim = -decr(p)
                r_out = np.where(delta < dt * lim, prev_r + lim * dt, r_out)
            out = np.where(inited, r_out, out)
            new[k_rate] = out
        if dbw != 0.0:
            half = dbw / 2.0
            out = np.where(out < -half, out + half, np.where(out > half, out - half, 0.0))
        if hyw != 0.0:
            ph = p[k_hyst]
            h = np.where(out > ph, np.maximum(ph, out - 0.5 * hyw),
                         np.where(out < ph, np.minimum(ph, out + 0.5 * hyw), out))
            out = np.where(inited, h, out)
            new[k_hyst] = out
        if bias != 0.0:
            out = out + bias
        stuck = p[fs] != 0.0
        out = np.where(stuck, p[k_prev], out)
        for k in list(new):  # a stuck actuator's filters stand still
            new[k] = np.where(stuck, p[k], new[k])
        new[k_prev] = out
        new[k_init] = np.ones_like(u)
        if clip is not None:
            vmin, vmax = clip[0](p), clip[1](p)
            out = np.minimum(np.maximum(out, vmin), vmax)
            s = ((out >= vmax) & (vmax != 0)) | ((out <= vmin) & (vmin != 0))
            new[sat] = s.astype(np.float64)
        new[name] = out
        return new

    saved_clip, b.clip = b.clip, None  # clipped above (before the saturation test)
    return b.done(compute, (sat,) if saved_clip is not None else ())


def _filter(el: ET.Element, ctx: Context) -> Component:
    tag = el.tag
    coeffs = {"lag_filter": 1, "washout_filter": 1, "lead_lag_filter": 4,
              "second_order_filter": 6, "integrator": 1}[tag]
    allowed = {f"c{i}" for i in range(1, coeffs + 1)} | ({"trigger"} if tag == "integrator"
                                                        else set())
    b = Build(el, ctx, allowed)
    b.input_count(1, 1)
    c = [0.0] * 7
    for i in range(1, coeffs + 1):
        e = one(el, f"c{i}", ctx)
        if e is not None:
            t = text(e)
            if not is_number(t):
                raise ctx.fail(e, f"a coefficient given as a property ({t!r}) is not "
                                  f"supported: give a number")
            c[i] = number(e, ctx)
    tr = one(el, "trigger", ctx)
    trigger = prop(text(tr), b.reads) if tr is not None else None
    x, name = b.inputs[0], b.name
    k_first = b.key("initialize")
    k_i1, k_i2, k_o1, k_o2 = (b.key("input_prev1"), b.key("input_prev2"),
                              b.key("output_prev1"), b.key("output_prev2"))
    # a filter's first run sets its past to the input it last held (0 at
    # load) and outputs that; an integrator's first run is an ordinary step
    # (both measured against JSBSim 1.3.3)
    first_run = 0.0 if tag == "integrator" else 1.0
    b.state.update({k_first: first_run, k_i1: 0.0, k_i2: 0.0, k_o1: 0.0, k_o2: 0.0})

    def coefficients(dt: float) -> tuple[float, ...]:
        if tag == "lag_filter":
            denom = 2.0 + dt * c[1]
            return dt * c[1] / denom, (2.0 - dt * c[1]) / denom
        if tag == "washout_filter":
            denom = 2.0 + dt * c[1]
            return 2.0 / denom, (2.0 - dt * c[1]) / denom
        if tag == "lead_lag_filter":
            denom = 2.0 * c[3] + dt * c[4]
            return ((2.0 * c[1] + dt * c[2]) / denom, (dt * c[2] - 2.0 * c[1]) / denom,
                    (2.0 * c[3] - dt * c[4]) / denom)
        if tag == "second_order_filter":
            denom = 4.0 * c[4] + 2.0 * c[5] * dt + c[6] * dt * dt
            return ((4.0 * c[1] + 2.0 * c[2] * dt + c[3] * dt * dt) / denom,
                    (2.0 * c[3] * dt * dt - 8.0 * c[1]) / denom,
                    (4.0 * c[1] - 2.0 * c[2] * dt + c[3] * dt * dt) / denom,
                    (2.0 * c[6] * dt * dt - 8.0 * c[4]) / denom,
                    (4.0 * c[4] - 2.0 * c[5] * dt + c[6] * dt * dt) / denom)
        return (dt * c[1] / 2.0,)

    def compute(p: Props, dt: float) -> dict[str, Any]:
        first = p[k_first] != 0.0
        u = np.asarray(x(p), dtype=np.float64)
        i1, i2, o1, o2 = p[k_i1], p[k_i2], p[k_o1], p[k_o2]
        k = coefficients(dt)
        if tag == "lag_filter":
            out = (u + i1) * k[0] + o1 * k[1]
        elif tag == "lead_lag_filter":
            out = u * k[0] + i1 * k[1] + o1 * k[2]
        elif tag == "second_order_filter":
            out = u * k[0] + i1 * k[1] + i2 * k[2] - o1 * k[3] - o2 * k[4]
        elif tag == "washout_filter":
            out = u * k[0] - i1 * k[0] + o1 * k[1]
        else:
            if trigger is not None:
                # a negative trigger resets the output to 0 first; one beyond
                # 1e-6 either way then holds it (the inputs are not added);
                # the past inputs follow the input all the while (measured
                # against JSBSim 1.3.3 at 1, 2e-6, 5e-7, -5e-7, -2e-6 and -1)
                test = trigger(p)
                o1 = np.where(test < 0.0, 0.0, o1)
                out = np.where(np.abs(test) > 0.000001, o1, u * k[0] + i1 * k[0] + o1)
            else:
                out = u * k[0] + i1 * k[0] + o1
        # the first frame: the output is the input held from before (0 at load)
        held = p[k_i1]  # JSBSim's Input member: the last input
        u = np.where(first, held, u)
        out = np.where(first, held, out)
        i1 = np.where(first, held, i1)
        o1 = np.where(first, held, o1)
        return {name: out, k_o2: o1, k_o1: out, k_i2: i1, k_i1: u,
                k_first: np.zeros_like(u)}
    return b.done(compute)


def _kinematic(el: ET.Element, ctx: Context) -> Component:
    b = Build(el, ctx, {"traverse", "noscale"})
    b.input_count(1, 1)
    tv = one(el, "traverse", ctx, need=True)
    assert tv is not None
    attrs(tv, ctx, set())
    pos: list[float] = []
    times: list[float] = []
    for s in kids(tv):
        if s.tag != "setting":
            raise ctx.fail(s, "is not supported in <traverse> (only <setting>)")
        for k in kids(s):
            if k.tag not in ("position", "time"):
                raise ctx.fail(k, "is not supported in <setting> (position, time)")
        pe, te = one(s, "position", ctx, need=True), one(s, "time", ctx, need=True)
        assert pe is not None and te is not None
        pos.append(number(pe, ctx))
        times.append(number(te, ctx))
    if len(pos) < 2:
        raise ctx.fail(tv, "needs two or more <setting>")
    if any(b2 <= a for a, b2 in zip(pos, pos[1:])):
        raise ctx.fail(tv, "setting positions must increase")
    scale = one(el, "noscale", ctx) is None
    det, tt = np.array(pos), np.array(times)
    inner = det[1:]
    x, name = b.inputs[0], b.name
    current = b.outputs[1] if len(b.outputs) > 1 else name

    def compute(p: Props, dt: float) -> dict[str, Any]:
        u = np.asarray(x(p), dtype=np.float64)
        if scale:
            u = u * det[-1]
        u = np.clip(u, det[0], det[-1])
        out = p[current].copy()
        left = np.full(u.shape, dt)
        for _ in range(len(det) + 1):
            live = (left > 0.0) & ~(np.abs(u - out) <= _EPS * np.maximum(np.abs(u), np.abs(out)))
            if not live.any():
                break
            ind = np.where(u < out, np.searchsorted(inner, out, "left"),
                           np.searchsorted(inner, out, "right")) + 1
            ind = np.minimum(ind, len(det) - 1)
            t = tt[ind]
            jump = live & (t <= 0.0)
            rate = (det[ind] - det[ind - 1]) / np.where(t > 0.0, t, 1.0)
            this_in = np.clip(u, det[ind - 1], det[ind])
            this_dt = np.abs((this_in - out) / rate)
            partial = left < this_dt
            moved = np.where(partial, np.where(out < u, out + left * rate, out - left * rate),
                             this_in)
            out = np.where(jump, u, np.where(live, moved, out))
            left = np.where(jump, 0.0, np.where(live, left - np.where(partial, left, this_dt),
                                                left))
        return {name: out}
    return b.done(compute)


#: the components with state
DYNAMIC: dict[str, Callable[[ET.Element, Context], Component]] = {
    "pid": _pid, "actuator": _actuator, "kinematic": _kinematic,
    "lag_filter": _filter, "lead_lag_filter": _filter, "washout_filter": _filter,
    "second_order_filter": _filter, "integrator": _filter,
}
