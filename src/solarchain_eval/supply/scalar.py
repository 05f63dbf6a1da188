"""The single env's specialised copy of :func:`~.dynamics.supply_step` on Python floats.

:func:`~.dynamics.supply_step` is written once for three arithmetic back-ends; on Python floats
each ``minimum``/``maximum``/``where`` is a function call and each region zips ten lists. This
module evaluates the same IEEE double operations in the same order with those calls written
out as the conditional expressions :class:`~.dynamics.ScalarOps` evaluates (``_minimum(a, b)`` is
``b if b < a else a``, ``_maximum(a, b)`` is ``b if b > a else a``) and with each day's per-region
inputs and the network's constants zipped once per env. Its outcome equals
``supply_step(SCALAR, ...)``'s bit for bit, NaN and infinities included
(tests/test_supply_scalar.py holds the two equal); a change to the dynamics is made in both.
"""

from __future__ import annotations

import sys

from .dynamics import (
    DAMPING_ELASTICITY,
    MAX_PRICE_RETURN,
    MIN_DEMAND_FACTOR,
    MIN_PRICE_INDEX,
    NORMAL_COVER_DAYS,
    PRICE_BACKLOG_WEIGHT,
    PRICE_COVER_WEIGHT,
    PRICE_DAMPING_WEIGHT,
    PRICE_INCENTIVE_WEIGHT,
    SupplyOutcome,
    SupplyParams,
    SupplyRewardWeights,
)

#: Whether the builtin ``sum`` of floats adds left to right in plain double arithmetic, as the loops of
#: ``supply_step`` do (CPython before 3.12; 3.12 made it a compensated sum, which rounds differently).
_SEQUENTIAL_SUM = sys.version_info < (3, 12)
_new_outcome = tuple.__new__  # SupplyOutcome from one tuple, without its Python-level __new__


class ScalarSupplyStep:
    """``supply_step(SCALAR, params, weights, ...)`` of one env on the days of ``orders``/``spoofed``/``levels``.

    Parameters
    ----------
    params, weights : SupplyParams, SupplyRewardWeights
        The network's constants and the reward's weights.
    orders, spoofed, levels : lists over days of lists over regions
        Each day's retailer orders (units), spoofed stock reports (bools) and the levels those
        reports show (units), as :class:`~.inputs.SupplyInputs` holds them.
    """

    def __init__(
        self, params: SupplyParams, weights: SupplyRewardWeights, orders: list, spoofed: list, levels: list
    ) -> None:
        constants = list(
            zip(
                params.spoilage_rate,
                params.production_capacity_units,
                [lead - 1 for lead in params.lead_time_days],  # the slot production enters
                params.lane_capacity_units,
                strict=True,
            )
        )
        #: Per day, per region: (orders, spoofed, level, spoilage, capacity, last slot, lane capacity).
        self.rows = [
            [(o, s, v, *c) for o, s, v, c in zip(day_orders, day_spoofed, day_levels, constants, strict=True)]
            for day_orders, day_spoofed, day_levels in zip(orders, spoofed, levels, strict=True)
        ]
        #: Per day: the orders' network total, summed over regions left to right as the step would.
        self.orders_total_units = []
        for day_orders in orders:
            total = 0.0
            for o in day_orders:
                total = total + o
            self.orders_total_units.append(total)
        self.scale_units = params.scale_units
        self.weights = weights
        w = weights
        self._weights = (w.drawdown, w.jitter, w.unmet, w.fairness, w.feasibility, w.feasibility_penalty)

    def __call__(
        self,
        on_hand_units: list,
        pipeline_units: list,
        backlog_units: list,
        price_index: float,
        peak_price_index: float,
        day: int,
        action: tuple,
        jitter: float,
        noise: float,
    ) -> SupplyOutcome:
        """The :class:`~.dynamics.SupplyOutcome` of one step on ``day`` (arguments as :func:`~.dynamics.supply_step`'s)."""
        incentive, release, damping = action
        damp = 1.0 - DAMPING_ELASTICITY * damping
        damp = damp if damp > MIN_DEMAND_FACTOR else MIN_DEMAND_FACTOR
        on_hand_next, pipeline_next, backlog_next, region_filled, region_effective, region_rate = [], [], [], [], [], []
        orders_t = self.orders_total_units[day]
        effective_t = reported_t = phantom_t = feasible_t = filled_t = delivered_t = 0.0
        unmet_t = production_t = arrivals_t = spoiled_t = on_hand_t = transit_t = 0.0
        # Not strict: every list has one entry per region by construction (a strict zip costs a keyword call).
        regions = zip(on_hand_units, pipeline_units, backlog_units, self.rows[day])  # noqa: B905
        for on_hand, slots, backlog, (orders, spoof, level, spoilage, capacity, last, lane) in regions:
            arrivals = slots[0]
            slots = [*slots[1:], 0.0]
            stock = on_hand + arrivals
            spoiled = stock * spoilage
            stock = stock - spoiled
            production = incentive * capacity
            slots[last] = slots[last] + production
            reported = level if spoof else stock
            phantom = reported - stock
            phantom = 0.0 if phantom < 0.0 else phantom
            effective = (orders + backlog) * damp
            filled = release * reported
            filled = effective if effective < filled else filled
            unmet = effective - filled
            due = slots[0]
            feasible = stock + due
            feasible = lane if lane < feasible else feasible
            delivered = feasible if feasible < filled else filled
            from_hand = stock if stock < delivered else delivered
            stock = stock - from_hand
            slots[0] = due - (delivered - from_hand)
            on_hand_next.append(stock)
            pipeline_next.append(slots)
            backlog_next.append(unmet)
            region_filled.append(filled)
            region_effective.append(effective)
            region_rate.append(filled / (1e-9 if effective < 1e-9 else effective))
            effective_t = effective_t + effective
            reported_t = reported_t + reported
            phantom_t = phantom_t + phantom
            feasible_t = feasible_t + feasible
            filled_t = filled_t + filled
            delivered_t = delivered_t + delivered
            unmet_t = unmet_t + unmet
            production_t = production_t + production
            arrivals_t = arrivals_t + arrivals
            spoiled_t = spoiled_t + spoiled
            on_hand_t = on_hand_t + stock
            if _SEQUENTIAL_SUM:
                transit_t = sum(slots, transit_t)
            else:
                for slot in slots:
                    transit_t = transit_t + slot
        n = len(region_rate)
        if _SEQUENTIAL_SUM:
            mean_rate = sum(region_rate, 0.0) / n
        else:
            mean_rate = 0.0
            for rate in region_rate:
                mean_rate = mean_rate + rate
            mean_rate = mean_rate / n
        fairness = 0.0
        for rate in region_rate:
            fairness = fairness + (rate - mean_rate) * (rate - mean_rate)
        fairness = fairness / n
        unsafe_t = filled_t - delivered_t
        scale = self.scale_units
        violation_rate = unsafe_t / (1e-9 if filled_t < 1e-9 else filled_t)
        cover_gap = (on_hand_t / scale - NORMAL_COVER_DAYS) / NORMAL_COVER_DAYS
        price_return = (
            -PRICE_COVER_WEIGHT * cover_gap
            + PRICE_DAMPING_WEIGHT * damping
            + PRICE_BACKLOG_WEIGHT * unmet_t / scale
            - PRICE_INCENTIVE_WEIGHT * incentive
            + noise
        )
        price_return = -MAX_PRICE_RETURN if price_return < -MAX_PRICE_RETURN else price_return
        price_return = MAX_PRICE_RETURN if price_return > MAX_PRICE_RETURN else price_return
        price = price_index * (1.0 + price_return)
        price = price if price > MIN_PRICE_INDEX else MIN_PRICE_INDEX
        peak_price = price if price > peak_price_index else peak_price_index
        drawdown = 1.0 - price / (1e-12 if peak_price < 1e-12 else peak_price)
        drawdown_w, jitter_w, unmet_w, fairness_w, feasibility_w, feasibility_penalty = self._weights
        reward = (
            filled_t / scale
            - drawdown_w * drawdown
            - jitter_w * jitter
            - unmet_w * unmet_t / scale
            - fairness_w * fairness
        )
        if feasibility_penalty:
            reward = reward - feasibility_w * (violation_rate + unsafe_t / scale)
        return _new_outcome(
            SupplyOutcome,
            (
                on_hand_next,
                pipeline_next,
                backlog_next,
                price,
                peak_price,
                reward,
                orders_t,
                effective_t,
                reported_t,
                phantom_t,
                feasible_t,
                filled_t,
                delivered_t,
                unsafe_t,
                release * phantom_t,
                unmet_t,
                production_t,
                arrivals_t,
                spoiled_t,
                on_hand_t,
                transit_t,
                violation_rate,
                drawdown,
                fairness,
                region_filled,
                region_effective,
                region_rate,
            ),
        )
