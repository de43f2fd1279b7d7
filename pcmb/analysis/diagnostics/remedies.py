"""The cause of a failure and the remedy named to the user in a ``chaos-unreliable`` record."""

from __future__ import annotations

import dataclasses
from collections.abc import Collection

import numpy as np
from numpy.typing import NDArray

from pcmb.analysis.diagnostics.check import STANDARD_NORMAL
from pcmb.analysis.diagnostics.decay import Expansion, coefficient_energies, decay_shape
from pcmb.analysis.diagnostics.phrases import as_percent
from pcmb.analysis.diagnostics.placed import interpolated
from pcmb.analysis.diagnostics.ranges import RANGE_SHARE
from pcmb.chaos.basis import tail_terms
from pcmb.chaos.elements import PiecewiseExpansion
from pcmb.chaos.expansion import ChaosExpansion
from pcmb.wording import plural

#: A tail holding more than this share of its energy in one input is "concentrated".
_CONCENTRATED = 0.75
#: An error that ends above this multiple of its value where it first failed grows.
_GROWTH = 2.0
#: The remedy reads the decay along every input holding at least this share of the tail.
_SHARED = 0.25
#: A held-out error whose weighted distance from the centre of an input's range
#: (:func:`error_at_ends`) is at least this sits at its ends: a smooth response.
_AT_ENDS = 0.75
#: ... and where it is at most this, inside it: around a jump, kink or steep front.
_INSIDE = 0.4
#: Either only where it lies that far from the 0.5 of an error spread evenly at this one-sided
#: confidence, given how many runs carry the error (:attr:`HeldOutPlace.carriers`): 8 drawn runs
#: of a two-input phase drift put it at 0.29, carried by 3 runs, at one seed of four.
_PLACE_CONFIDENCE = 0.95
#: The variance of |2u - 1|, u uniform in (0, 1): the spread of one run's distance from the
#: centre where the error is spread evenly.
_SPREAD_VARIANCE = 1 / 12
#: Energies falling as p^-s with s at most this sum to infinity: no response of finite
#: variance has such a tail (a jump's s is about 2, a kink's 4), a spectrum not yet falling.
_SUMMABLE = 1.0
#: The energy of a degree below this share of its spectrum's peak is round-off or the
#: simulator's noise, which no decay reads.
_FLOOR = 1e-12


def remedy_for(
    expansion: Expansion,
    estimate: NDArray[np.float64],
    failing: NDArray[np.bool_],
    out_of_range_share: NDArray[np.float64],
    budgets: Collection[str],
    held_out: HeldOutPlace | None = None,
    by_element: str = "",
    runs: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
) -> str:
    """What may help (:func:`_cause_remedy`, reading the design's ``runs``: their (N, n) germ
    and (N, T) values), turned away from a refinement that already ran out (``budgets``: the
    codes of the design's budget records), with where a multi-element surrogate's error sits
    (``by_element``, :func:`element_errors`) and what was tried: the order, the elements and
    the refinement's end."""
    action, inputs, cause = _cause_remedy(
        expansion, estimate, failing, out_of_range_share, held_out, runs
    )
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
    if isinstance(expansion, PiecewiseExpansion):
        more = "raise method.max_elements" if "element-budget" in budgets else "finer cuts, or auto"
        split = f"more elements{along} (method.elements: {more})"
    else:
        split = f"multi-element chaos{along} (method.elements)"
    raise_order = f"raising the order{' of ' + inputs if inputs else ''} (method.order)"
    if action == "sampling":
        remedy = "sampling (method.kind: montecarlo, lhs or sobol)"
    elif action != "elements" and "order-budget" in budgets:
        remedy = f"{split} or an order above {order} set by hand (method.order)"
    elif action == "order":
        remedy = raise_order
    elif action == "elements":
        remedy = split
    else:
        remedy = f"{raise_order}, or, if the response has a jump or kink in {inputs}, {split}"
    remedy = f"{remedy}: {cause}"
    if by_element:
        remedy = f"{remedy}; {by_element}"
    return f"{remedy}; tried: {'; '.join(tried)}"


@dataclasses.dataclass(frozen=True)
class HeldOutPlace:
    """The held-out runs' errors where the verdict fails, which the remedy reads
    (:func:`error_at_ends`)."""

    #: (K, n) the runs' germ.
    germ: NDArray[np.float64]
    #: (K, T) the model's value at each run.
    observed: NDArray[np.float64]
    #: (K, T) the model's value less the surrogate's at each run.
    residual: NDArray[np.float64]
    #: (n,) along each input, the mean of |2u - 1|, u the runs' ranks along it in (0, 1),
    #: weighted by their squared error over the failing times: 0.5 for an error spread
    #: evenly, near 1 for one at the ends of the range, lower for one around a point inside.
    ends: NDArray[np.float64]
    #: How many runs carry the error: (Σw)² / Σw², w the weights of ``ends``.
    carriers: float

    def where(self, k: int) -> str:
        """``"ends"`` or ``"inside"`` where the error along input k sits at the ends of its
        range (``ends`` at least ``_AT_ENDS``) or inside it (at most ``_INSIDE``), each only
        if that far from an even spread's 0.5 at ``_PLACE_CONFIDENCE`` given the
        ``carriers``; else ``""``."""
        if not self.carriers > 0:
            return ""
        noise = np.sqrt(_SPREAD_VARIANCE / self.carriers) * STANDARD_NORMAL.inv_cdf(
            _PLACE_CONFIDENCE
        )
        if self.ends[k] >= max(_AT_ENDS, 0.5 + noise):
            return "ends"
        if self.ends[k] <= min(_INSIDE, 0.5 - noise):
            return "inside"
        return ""


def error_at_ends(
    germ: NDArray[np.float64],
    observed: NDArray[np.float64],
    predicted: NDArray[np.float64],
    failing: NDArray[np.bool_],
) -> HeldOutPlace:
    """Where along each input the (K, T) held-out error, ``observed`` less ``predicted``,
    sits over the failing times (:class:`HeldOutPlace`): near the ends of the range for a
    smooth response converging slowly, around a point inside it for a jump or kink there."""
    residual = observed - predicted
    ranks = np.argsort(np.argsort(germ, axis=0), axis=0)
    distance = np.abs(2 * (ranks + 0.5) / germ.shape[0] - 1)
    size = np.max(np.abs(residual[:, failing]))
    if not size > 0 or not np.isfinite(size):
        return HeldOutPlace(germ, observed, residual, np.full(germ.shape[1], 0.5), 0.0)
    weight = np.sum((residual[:, failing] / size) ** 2, axis=1)
    carriers = float(weight.sum() ** 2 / np.sum(weight**2))
    return HeldOutPlace(germ, observed, residual, weight @ distance / weight.sum(), carriers)


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


def _decay_read(name: str, kind: str, rate: float, first: int, last: int, whose: str) -> str:
    """The decay of ``whose`` coefficients along one input (:func:`decay_shape`) in words."""
    if kind == "geometric":
        return (
            f"{whose} along {name} fall geometrically (energy × {rate:.2g} per degree, degrees "
            f"{first} to {last}), as those of a smooth response, which a higher order resolves"
        )
    return (
        f"{whose} along {name} fall algebraically (energy ~ p^-{rate:.2g}, degrees {first} to "
        f"{last}), as those of a jump or a kink, which a higher order resolves only slowly"
    )


#: Whose coefficients :func:`_decay_read` reads from the expansion itself.
_OWN = "the chaos coefficients"


def _held_out_decay(
    expansion: Expansion,
    held_out: HeldOutPlace | None,
    runs: tuple[NDArray[np.float64], NDArray[np.float64]] | None,
    failing: NDArray[np.bool_],
) -> tuple[tuple[str, float, int, int], str] | None:
    """The decay (:func:`decay_shape`) of the interpolant through the N design ``runs`` ((N, 1)
    germ, (N, T) values) of a one-input expansion and its K held-out runs, of degree N + K - 1,
    each failing time weighing the same, read up to the degree where its energy falls below
    ``_FLOOR`` of its peak; with whose coefficients they are, in words. ``None`` for several
    inputs or elements, without the design's or held-out runs, or with too few degrees to
    read."""
    if not isinstance(expansion, ChaosExpansion) or expansion.n != 1:
        return None
    if held_out is None or runs is None:
        return None
    (distribution,) = expansion.distributions
    design_germ, design_values = runs
    points = np.concatenate([design_germ[:, 0], held_out.germ[:, 0]])
    values = np.vstack([design_values, held_out.observed])[:, failing]
    finite = np.isfinite(values).all(axis=1)
    points, values = points[finite], values[finite]
    size = np.max(np.abs(values), initial=0.0)
    if not size > 0:
        return None
    try:
        coefficients = interpolated(distribution.family, points, values / size)
    except np.linalg.LinAlgError:  # a held-out run on a node
        return None
    energies = coefficients[1:] ** 2
    variance = energies.sum(axis=0)
    varies = np.isfinite(variance) & (variance > 0)
    energy = np.concatenate([[0.0], np.sum(energies[:, varies] / variance[varies], axis=1)])
    paired = energy[1:-1] + energy[2:]
    below = np.flatnonzero(paired < _FLOOR * paired.max(initial=0.0))
    degrees = points.size if below.size == 0 else below[0] + 2
    shape = decay_shape(energy[:degrees], np.arange(degrees)[:, None], 0)
    made = design_germ.shape[0]
    whose = (
        f"the coefficients of the interpolant through the design's {finite[:made].sum()} runs "
        f"and the {finite[made:].sum()} held-out runs"
    )
    return None if shape is None else (shape, whose)


def _peaks_past_first(energy: NDArray[np.float64], index: NDArray[np.int64], k: int) -> bool:
    """Whether the ``energy`` of the terms (of ``index``) along input k peaks past its first
    degree, by degree and by pairs of neighbouring degrees (as :func:`decay_shape` reads them: a
    response even or odd about the centre has every other coefficient zero)."""
    by_degree = np.bincount(index[:, k], weights=energy)[1:]
    pairs = by_degree[:-1] + by_degree[1:]
    return pairs.size > 0 and by_degree.argmax() > 0 and pairs.argmax() > 0


def _cause_remedy(
    expansion: Expansion,
    estimate: NDArray[np.float64],
    failing: NDArray[np.bool_],
    out_of_range_share: NDArray[np.float64],
    held_out: HeldOutPlace | None,
    runs: tuple[NDArray[np.float64], NDArray[np.float64]] | None,
) -> tuple[str, str, str]:
    """What may help, read from where the tail's energy sits over the failing times:
    ``(action, inputs, cause)``, the action ``"sampling"``, ``"order"``, ``"elements"`` or
    ``"either"`` (a higher order first) along the named inputs (``""``: all), the cause in
    words.

    - energy spread over several inputs and an error that grows (more than doubles from
      the first failing time to the end): chaotic or long-horizon dynamics, which no
      order fixes — sampling;
    - else, along every input that holds at least ``_SHARED`` of the tail (each failing
      time weighing the same), the decay of the coefficients (:func:`decay_shape`):
      algebraic along any, as those of a jump or kink — multi-element chaos along those,
      unless, past a peak above the first degree or slower than ``_SUMMABLE`` from the
      first, the interpolant through the design's and the held-out runs of a one-input
      expansion (:func:`_held_out_decay`), reading past the own top degree, decays
      geometrically — a higher order;
      geometric along all, as those of an analytic response — a higher order, unless the
      held-out error sits inside the input's range (:meth:`HeldOutPlace.where`), or, where too
      few runs carry it to tell, lies below ``_INSIDE`` while the interpolant through the
      design's and the held-out runs of a one-input expansion (:func:`_held_out_decay`) decays
      algebraically: a kink whose first degrees look geometric — multi-element chaos;
    - too few degrees to tell: the decay of that interpolant, algebraic — multi-element
      chaos, geometric — a higher order; without it, a higher order when the held-out error
      sits at the ends of the input's range, as that of a smooth response; multi-element chaos
      when it sits inside, around a jump or kink; else a higher order when the energy along
      the input peaks past its first degree (:func:`_peaks_past_first`): more extrema than
      the order holds, as a phase drifting over a long horizon, where a jump's or kink's
      spectrum peaks at its first degree; else either, a higher order first (the cheaper
      try), and the message says that the order was too low to tell.
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
    richer = _held_out_decay(expansion, held_out, runs, failing)
    richer_read = "" if richer is None else _decay_read(name, *richer[0], richer[1])
    where = "" if held_out is None else held_out.where(top)
    place = ""
    if held_out is not None:
        sits = {"ends": "at the ends of", "inside": "inside", "": "over"}[where]
        place = (
            f"the surrogate's error at the held-out runs sits {sits} the range of {name} (mean "
            f"|2u - 1| of their ranks u along it, weighted by the squared error: "
            f"{held_out.ends[top]:.2f}, carried by about {held_out.carriers:.2g} runs; 0.5 if "
            "spread evenly)"
        )
    if top in read:
        reads = "; ".join(_decay_read(expansion.names[k], *shapes[k], _OWN) for k in read)
        jumps = [expansion.names[k] for k in read if shapes[k][0] == "algebraic"]
        # The few top degrees of a still unresolved oscillation may fall as a jump's: past a
        # late peak (a jump's spectrum peaks at its first degree), or barely, from degree 1,
        # slower than any finite variance's tail. The richer interpolant, reading further
        # than the own top degree, tells.
        _, rate, first, last = shapes[top]
        unresolved = ""
        if first > 1:
            unresolved = f"that is past a peak at degree {first} (a jump's is at degree 1)"
        elif shapes[top][0] == "algebraic" and rate <= _SUMMABLE:  # p^-rate, not a ratio
            unresolved = f"that is slower than any finite variance's tail (p^-{_SUMMABLE:g})"
        further = richer is not None and richer[0][0] == "geometric" and richer[0][3] > last
        if jumps and unresolved and further:
            return "order", name, f"{reads}; but {unresolved}, and {richer_read}"
        if jumps:
            return "elements", " and ".join(jumps), reads
        # A kink's first degrees may look geometric: the held-out error sits inside the range,
        # or, where too few runs carry it to tell, the richer interpolant decays algebraically.
        kink = where == "inside" or (
            held_out is not None
            and held_out.ends[top] <= _INSIDE
            and richer is not None
            and richer[0][0] == "algebraic"
        )
        if kink:
            but = place if where == "inside" else f"{place}, and {richer_read}"
            return "elements", name, f"{reads}, but {but}, around a kink or steep front"
        return "order", " and ".join(expansion.names[k] for k in read), reads
    order = int(index[:, top].max())
    unknown = (
        f"; at order {order} too few degrees follow the peak of the spectrum along {name} "
        "to tell a jump or kink from a slowly converging smooth response by it"
    )
    if richer is not None:
        action = "elements" if richer[0][0] == "algebraic" else "order"
        return action, name, f"{richer_read}{unknown} alone"
    if where == "ends":
        return "order", name, f"{place}, as that of a smooth response converging slowly{unknown}"
    if where == "inside":
        return "elements", name, f"{place}, around a jump, kink or steep front{unknown}"
    if _peaks_past_first(energy, index, top):
        return (
            "order",
            name,
            f"the energy of the chaos coefficients along {name} peaks past its first degree: "
            "an oscillation that the order does not yet resolve, as a smooth response's "
            "spectrum rises to its peak before it falls geometrically (a jump's or kink's "
            f"peaks at the first degree and falls algebraically){unknown}",
        )
    previous = energy[before].sum()
    if previous > 0:
        read = (
            f"the outer two layers of its spectrum hold {energy[tail].sum() / previous:.2g} "
            "times the energy of the layers before them"
        )
    else:  # order 2: no layer before the tail
        overshoots = np.any(out_of_range_share[failing] > RANGE_SHARE)
        read = f"the surrogate {'leaves' if overshoots else 'stays within'} the runs' range"
    spread = f"; {place}" if place else ""
    # Raising the order by one costs a run per line of nodes, elements at least double them.
    return "either", name, f"{read}{spread}{unknown}; a higher order is the cheaper try"
