"""The cause of a failure and the remedy named to the user in a ``chaos-unreliable`` record."""

from __future__ import annotations

from collections.abc import Collection

import numpy as np
from numpy.typing import NDArray

from pcmb.analysis.diagnostics.decay import Expansion, coefficient_energies, decay_shape
from pcmb.analysis.diagnostics.phrases import as_percent
from pcmb.analysis.diagnostics.ranges import RANGE_SHARE
from pcmb.chaos.basis import tail_terms
from pcmb.chaos.elements import PiecewiseExpansion
from pcmb.wording import plural

#: A tail holding more than this share of its energy in one input is "concentrated".
_CONCENTRATED = 0.75
#: An error that ends above this multiple of its value where it first failed grows.
_GROWTH = 2.0
#: A tail holding at least this share of the energy of the two layers before it does not
#: decay as an analytic response's does, over the degrees the expansion has.
_FLAT = 0.5
#: The remedy reads the decay along every input holding at least this share of the tail.
_SHARED = 0.25
#: A held-out error whose weighted distance from the centre of an input's range
#: (:func:`error_at_ends`) is at least this sits at its ends: a smooth response.
_AT_ENDS = 0.75
#: ... and where it is at most this, inside it: around a jump, kink or steep front.
_INSIDE = 0.4


def remedy_for(
    expansion: Expansion,
    estimate: NDArray[np.float64],
    failing: NDArray[np.bool_],
    out_of_range_share: NDArray[np.float64],
    budgets: Collection[str],
    ends: NDArray[np.float64] | None = None,
    by_element: str = "",
) -> str:
    """What may help (:func:`_cause_remedy`), turned away from a refinement that already ran
    out (``budgets``: the codes of the design's budget records), with where a multi-element
    surrogate's error sits (``by_element``, :func:`element_errors`) and what was tried: the
    order, the elements and the refinement's end."""
    action, inputs, cause = _cause_remedy(expansion, estimate, failing, out_of_range_share, ends)
    orders = expansion.multi_index.max(axis=0)
    order = int(orders.max())
    elements = expansion.partition.size if isinstance(expansion, PiecewiseExpansion) else 1
    shown = f"order {order}" if orders.min() == order else f"orders {'x'.join(map(str, orders))}"
    tried = [f"{shown}, {plural(elements, 'element')}"]
    along = f" along {inputs}" if inputs else ""
    if "order-budget" in budgets:
        tried.append(f"order: auto ended at order {order} (order-budget)")
    if "element-budget" in budgets:
        tried.append(f"elements: auto ended at {elements} elements (element-budget)")
    if action == "sampling":
        remedy = f"sampling (method.kind: montecarlo, lhs or sobol): {cause}"
    elif action == "order" and "order-budget" in budgets:
        remedy = (
            f"multi-element chaos{along} (method.elements) or an order above {order} set by "
            f"hand (method.order): {cause}"
        )
    elif action == "order":
        remedy = f"raising the order{' of ' + inputs if inputs else ''} (method.order): {cause}"
    elif isinstance(expansion, PiecewiseExpansion):
        more = "raise method.max_elements" if "element-budget" in budgets else "finer cuts, or auto"
        remedy = f"more elements{along} (method.elements: {more}): {cause}"
    else:
        remedy = f"multi-element chaos{along} (method.elements): {cause}"
    if by_element:
        remedy = f"{remedy}; {by_element}"
    return f"{remedy}; tried: {'; '.join(tried)}"


def error_at_ends(
    germ: NDArray[np.float64], residual: NDArray[np.float64], failing: NDArray[np.bool_]
) -> NDArray[np.float64]:
    """(n,) where along each input the (K, T) held-out residual sits over the failing times:
    the mean of |2u - 1|, u the runs' ranks along the input in (0, 1), weighted by the
    squared residual; 0.5 for an error spread evenly, near 1 for one at the ends of the
    range (a smooth response converging slowly), lower for one around a point inside it."""
    ranks = np.argsort(np.argsort(germ, axis=0), axis=0)
    distance = np.abs(2 * (ranks + 0.5) / germ.shape[0] - 1)
    size = np.max(np.abs(residual[:, failing]))
    if not size > 0 or not np.isfinite(size):
        return np.full(germ.shape[1], 0.5)
    weight = np.sum((residual[:, failing] / size) ** 2, axis=1)
    return weight @ distance / weight.sum()


def element_errors(
    expansion: PiecewiseExpansion,
    germ: NDArray[np.float64],
    residual: NDArray[np.float64],
    failing: NDArray[np.bool_],
) -> str:
    """Which element holds the largest share of the (K, T) held-out squared error over the
    failing times, with its box and probability: an error far above the element's
    probability sits around a jump or kink there, one in proportion to it is spread."""
    partition = expansion.partition
    size = np.max(np.abs(residual[:, failing]))
    if partition.size < 2 or not size > 0 or not np.isfinite(size):
        return ""
    theta = np.column_stack(
        [d.to_physical(germ[:, k]) for k, d in enumerate(expansion.distributions)]
    )
    where = partition.locate(theta)
    weight = np.sum((residual[:, failing] / size) ** 2, axis=1)
    inside = where >= 0
    shares = np.bincount(where[inside], weights=weight[inside], minlength=partition.size)
    shares = shares / weight.sum()
    e = int(np.argmax(shares))
    support = np.array([d.physical.support() for d in expansion.distributions], dtype=float)
    bounds = zip(expansion.names, partition.bounds[e], support, strict=True)
    box = ", ".join(
        f"{name} in [{low:.4g}, {high:.4g}]"
        for name, (low, high), whole in bounds
        if low > whole[0] or high < whole[1]
    )
    return (
        f"element {e} ({box}) holds {as_percent(shares[e])} of the held-out squared error "
        f"where the verdict fails, for {as_percent(partition.probability[e])} of the probability"
    )


def _decay_read(name: str, kind: str, rate: float, first: int, last: int) -> str:
    """The decay of the chaos coefficients along one input (:func:`decay_shape`) in words."""
    if kind == "geometric":
        return (
            f"the chaos coefficients along {name} fall geometrically (energy × {rate:.2g} per "
            f"degree, degrees {first} to {last}), as those of a smooth response, which a "
            "higher order resolves"
        )
    return (
        f"the chaos coefficients along {name} fall algebraically (energy ~ p^-{rate:.2g}, "
        f"degrees {first} to {last}), as those of a jump or a kink, which a higher order "
        "resolves only slowly"
    )


def _cause_remedy(
    expansion: Expansion,
    estimate: NDArray[np.float64],
    failing: NDArray[np.bool_],
    out_of_range_share: NDArray[np.float64],
    ends: NDArray[np.float64] | None,
) -> tuple[str, str, str]:
    """What may help, read from where the tail's energy sits over the failing times:
    ``(action, inputs, cause)``, the action ``"sampling"``, ``"order"`` or ``"elements"``
    along the named inputs (``""``: all), the cause in words.

    - energy spread over several inputs and an error that grows (more than doubles from
      the first failing time to the end): chaotic or long-horizon dynamics, which no
      order fixes — sampling;
    - else, along every input that holds at least ``_SHARED`` of the tail (each failing
      time weighing the same), the decay of the coefficients (:func:`decay_shape`):
      algebraic along any, as those of a jump or kink — multi-element chaos along those;
      geometric along all, as those of an analytic response — a higher order, unless the
      held-out error sits inside the input's range (at most ``_INSIDE``, below), as a
      kink's does whose first degrees look geometric — multi-element chaos;
    - too few degrees to tell: a higher order when the held-out error sits at the ends of
      the input's range (``ends``, :func:`error_at_ends`, at least ``_AT_ENDS``), as that
      of a smooth response; multi-element chaos when it sits inside (at most ``_INSIDE``),
      around a jump or kink; else, with the error over the range, steep, oscillating or
      discontinuous when the spectrum does not decay (the outer two layers hold at least
      half the energy of the layers before them, the linear ones at order 3, the response's
      structure still rising at the top degree when they hold more) or, below order 3, the
      surrogate overshoots the runs — multi-element chaos; otherwise a higher order. The
      message says that the order was too low to tell.
    """
    index = expansion.multi_index
    tail = tail_terms(index)
    # The two layers before the tail, the linear terms among them up to order 4 (at order 3
    # they are the only layer before it).
    before = tail_terms(index, 4, lowest=1) & ~tail
    # Each failing time weighs the same: its energies as shares of its own variance.
    energies = coefficient_energies(expansion)[:, failing]
    variance = energies[np.any(index > 0, axis=1)].sum(axis=0)
    varies = np.isfinite(variance) & (variance > 0)
    energy = np.nansum(energies[:, varies] / variance[varies], axis=1)
    by_input = (index[tail] > 0).T.astype(float) @ energy[tail]
    total = by_input.sum()
    top = int(np.argmax(by_input))
    name = expansion.names[top]
    if total <= 0:
        return "order", "", "the outer two layers of the expansion carry no energy to read"
    grows = estimate[-1] > _GROWTH * estimate[np.argmax(failing)]
    if expansion.n > 1 and by_input[top] < _CONCENTRATED * total and grows:
        return (
            "sampling",
            "",
            "the error grows with time and spreads over the inputs, as in chaotic or "
            "long-horizon dynamics, which a higher order does not fix",
        )
    holders = [int(k) for k in np.argsort(-by_input) if by_input[k] >= _SHARED * total]
    shapes = {k: decay_shape(energy, index, k) for k in holders}
    read = [k for k in holders if shapes[k] is not None]  # too few degrees: not read
    place = ""
    if ends is not None:
        place = (
            f"the range of {name} (mean |2u - 1| of their ranks u along it, weighted by the "
            f"squared error: {ends[top]:.2f}; 0.5 if spread evenly)"
        )
    if top in read:
        reads = "; ".join(_decay_read(expansion.names[k], *shapes[k]) for k in read)
        jumps = [expansion.names[k] for k in read if shapes[k][0] == "algebraic"]
        if jumps:
            return "elements", " and ".join(jumps), reads
        if place and ends[top] <= _INSIDE:  # a kink's first degrees may look geometric
            return (
                "elements",
                name,
                f"{reads}, but the surrogate's error at the held-out runs sits inside {place}, "
                "around a kink or steep front there",
            )
        return "order", " and ".join(expansion.names[k] for k in read), reads
    order = int(index[:, top].max())
    unknown = (
        f"; at order {order} too few degrees follow the peak of the spectrum along {name} "
        "to tell a jump or kink from a slowly converging smooth response by it"
    )
    previous = energy[before].sum()
    if place and ends[top] >= _AT_ENDS:
        return (
            "order",
            name,
            f"the surrogate's error at the held-out runs sits at the ends of {place}, as "
            f"that of a smooth response converging slowly{unknown}",
        )
    if place and ends[top] <= _INSIDE:
        return (
            "elements",
            name,
            f"the surrogate's error at the held-out runs sits inside {place}, around a "
            f"jump, kink or steep front there{unknown}",
        )
    if previous > 0:
        ratio = energy[tail].sum() / previous
        steep = ratio >= _FLAT
        read = (
            f"the outer two layers of its spectrum hold {ratio:.2g} times the energy of the "
            "layers before them"
        )
    else:  # order 2: no layer before the tail, the overshoot tells
        steep = bool(np.any(out_of_range_share[failing] > RANGE_SHARE))
        read = f"the surrogate {'leaves' if steep else 'stays within'} the runs' range"
    if not steep:
        return "order", name, f"{read}: a smooth response converging slowly{unknown}"
    spread = ", with the surrogate's error over the range, not at its ends" if place else ""
    return (
        "elements",
        name,
        f"the response is steep, oscillating or discontinuous in {name}: {read}{spread}{unknown}",
    )
