"""Explicit embedded Runge–Kutta pairs that step a stacked batch with per-node error control.

A batch of B independent systems of d states is one vector of n = d·B values: the (d, B)
state raveled row-major. The pairs are tableaus -- :data:`RK23` (Bogacki–Shampine 3(2)),
:data:`RK45` (Dormand–Prince 5(4)) and :data:`DOP853` (Dormand–Prince 8(5,3)) -- served by
one step function (:func:`rk_step`), one starting-step rule (:func:`initial_step`) and one
step-size rule (:func:`step_factor`). A step is accepted when every node's own error norm,
computed as a separate run of that node would, is below 1 (:meth:`EmbeddedPair.error_norm`).

Stages, step control, starting step, dense output and the sampling of output times repeat
``scipy.integrate.solve_ivp`` with the same method (scipy 1.17) operation for operation; a
batch of one node differs from it only in the rounding of the error norm.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pcmb.errors import ModelError

__all__ = [
    "DOP853",
    "PAIRS",
    "RK23",
    "RK45",
    "DOP853Pair",
    "EmbeddedPair",
    "PolynomialPair",
    "initial_step",
    "integrate",
    "node_rms",
    "rk_step",
    "rms",
    "step_factor",
]

Rhs = Callable[[float, NDArray[np.float64]], NDArray[np.float64]]
Interpolant = Callable[[NDArray[np.float64]], NDArray[np.float64]]

# Step-size rule: the asymptotic proposal times SAFETY, kept within [MIN_FACTOR, MAX_FACTOR]
# of the current step (Hairer, Nørsett & Wanner, Solving ODEs I, Sec. II.4; scipy's values).
SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0


# =========================================================================== pairs


@dataclass(frozen=True, eq=False)
class EmbeddedPair(ABC):
    """An explicit Runge–Kutta method with an embedded error estimate (its Butcher tableau).

    A step of size h computes s stages ``k_i = f(t + c_i h, y + h Σ_j a_ij k_j)``, the new
    state ``y_new = y + h Σ_i b_i k_i`` (local extrapolation: the higher order is kept) and
    stage s, ``k_s = f(t + h, y_new)``, which is the next step's first stage.

    Attributes
    ----------
    name:
        The method's name (as in ``scipy.integrate.solve_ivp(method=...)``).
    order:
        Order of ``y_new``.
    error_order:
        The error estimate is O(h^(error_order + 1)); steps scale with its
        (error_order + 1)-th root.
    c:
        Nodes, shape (s,).
    a:
        Coefficients, shape (s, s), strictly lower triangular.
    b:
        Weights of ``y_new``, shape (s,).
    e:
        Error weights over the s + 1 stages, shape (s + 1,): the estimate is ``h Σ_i e_i k_i``.
    """

    name: str
    order: int
    error_order: int
    c: NDArray[np.float64]
    a: NDArray[np.float64]
    b: NDArray[np.float64]
    e: NDArray[np.float64]

    @property
    def stages(self) -> int:
        """Number of stages s (without the first-same-as-last stage)."""
        return self.c.size

    def stage_storage(self, n: int) -> NDArray[np.float64]:
        """Uninitialised stage rows for :func:`rk_step` and the dense output, (s + 1, n)."""
        return np.empty((self.stages + 1, n))

    def error_norm(
        self, K: NDArray[np.float64], h: float, scale: NDArray[np.float64], n_nodes: int
    ) -> float:
        """Largest per-node RMS of the error estimate divided by ``scale``.

        Parameters
        ----------
        K:
            Stage derivatives of the step, (s + 1, n) with n = d·B.
        h:
            Step size.
        scale:
            Tolerance scale ``atol + rtol·max(|y|, |y_new|)``, (n,).
        n_nodes:
            B: the state vector is a raveled (d, B) array.
        """
        return node_rms(np.dot(K.T, self.e) * h / scale, n_nodes)

    @abstractmethod
    def interpolant(
        self,
        fun: Rhs,
        t_old: float,
        y_old: NDArray[np.float64],
        y: NDArray[np.float64],
        h: float,
        stages: NDArray[np.float64],
    ) -> Interpolant:
        """Dense output over the step from ``(t_old, y_old)`` to ``(t_old + h, y)``.

        ``stages`` is the :meth:`stage_storage` the step filled (extra rows may be computed
        here, calling ``fun``). Returns a function mapping times (m,) to states (n, m).
        """


@dataclass(frozen=True, eq=False)
class PolynomialPair(EmbeddedPair):
    """A pair whose dense output is a polynomial in θ = (t − t_old)/h from the step's stages.

    Attributes
    ----------
    p:
        Shape (s + 1, k): the interpolant is ``y_old + h Σ_j (Σ_i k_i p_ij) θ^(j+1)``, a
        polynomial of degree k.
    """

    p: NDArray[np.float64]

    def interpolant(
        self,
        fun: Rhs,
        t_old: float,
        y_old: NDArray[np.float64],
        y: NDArray[np.float64],
        h: float,
        stages: NDArray[np.float64],
    ) -> Interpolant:
        q = stages[: self.stages + 1].T.dot(self.p)  # (n, k)

        def sample(times: NDArray[np.float64]) -> NDArray[np.float64]:
            theta = (times - t_old) / h
            powers = np.cumprod(np.tile(theta, (self.p.shape[1], 1)), axis=0)
            values = h * np.dot(q, powers)
            values += y_old[:, None]
            return values

        return sample


@dataclass(frozen=True, eq=False)
class DOP853Pair(EmbeddedPair):
    """Dormand–Prince 8(5,3): two error estimates and a 7th-order dense output.

    ``e`` is the 5th-order estimate; with the 3rd-order one ``e3`` the norm of Hairer's
    DOP853, ``|h| ‖e5‖² / √((‖e5‖² + 0.01 ‖e3‖²) d)``, behaves as O(h⁸). The dense output takes
    three more stages.

    Attributes
    ----------
    e3:
        Weights of the 3rd-order error estimate, shape (s + 1,).
    c_extra:
        Nodes of the extra stages, shape (3,).
    a_extra:
        Their coefficients over all earlier stages, shape (3, s + 4).
    d:
        Coefficients of the 4th to 7th interpolant terms over all stages, shape (4, s + 4).
    """

    e3: NDArray[np.float64]
    c_extra: NDArray[np.float64]
    a_extra: NDArray[np.float64]
    d: NDArray[np.float64]

    def stage_storage(self, n: int) -> NDArray[np.float64]:
        """Uninitialised stage rows, (s + 4, n): the step's s + 1 and the dense output's 3."""
        return np.empty((self.stages + 1 + self.c_extra.size, n))

    def error_norm(
        self, K: NDArray[np.float64], h: float, scale: NDArray[np.float64], n_nodes: int
    ) -> float:
        """Largest per-node DOP853 norm, each over that node's d states (see the class)."""
        err5 = np.sum((K.T @ self.e / scale).reshape(-1, n_nodes) ** 2, axis=0)
        err3 = np.sum((K.T @ self.e3 / scale).reshape(-1, n_nodes) ** 2, axis=0)
        denominator = err5 + 0.01 * err3
        d = scale.size // n_nodes
        active = denominator > 0  # a node with both estimates zero has zero error
        norms = np.zeros_like(err5)
        norms[active] = abs(h) * err5[active] / np.sqrt(denominator[active] * d)
        return float(np.max(norms))

    def interpolant(
        self,
        fun: Rhs,
        t_old: float,
        y_old: NDArray[np.float64],
        y: NDArray[np.float64],
        h: float,
        stages: NDArray[np.float64],
    ) -> Interpolant:
        first = self.stages + 1
        for s, (a, c) in enumerate(zip(self.a_extra, self.c_extra, strict=True), start=first):
            dy = np.dot(stages[:s].T, a[:s]) * h
            stages[s] = fun(t_old + c * h, y_old + dy)
        f_old, f_new = stages[0], stages[self.stages]
        delta_y = y - y_old
        terms = np.empty((3 + self.d.shape[0], y.size))
        terms[0] = delta_y
        terms[1] = h * f_old - delta_y
        terms[2] = 2 * delta_y - h * (f_new + f_old)
        terms[3:] = h * np.dot(self.d, stages)

        def sample(times: NDArray[np.float64]) -> NDArray[np.float64]:
            theta = ((times - t_old) / h)[:, None]
            values = np.zeros((theta.shape[0], y.size))
            # Horner form in θ and 1 − θ alternately, from the highest term down.
            for i, term in enumerate(reversed(terms)):
                values += term
                values *= theta if i % 2 == 0 else 1 - theta
            values += y_old
            return values.T

        return sample


# Bogacki & Shampine, "A 3(2) pair of Runge-Kutta formulas", Appl. Math. Lett. 2 (1989):
# error weights b̂ − b (b̂ the 2nd-order weights over four stages), cubic Hermite dense output.
RK23 = PolynomialPair(
    name="RK23",
    order=3,
    error_order=2,
    c=np.array([0, 1 / 2, 3 / 4]),
    a=np.array([[0, 0, 0], [1 / 2, 0, 0], [0, 3 / 4, 0]]),
    b=np.array([2 / 9, 1 / 3, 4 / 9]),
    e=np.array([5 / 72, -1 / 12, -1 / 9, 1 / 8]),
    p=np.array([[1, -4 / 3, 5 / 9], [0, 1, -2 / 3], [0, 4 / 3, -8 / 9], [0, -1, 1]]),
)

# Dormand & Prince, "A family of embedded Runge-Kutta formulae", J. Comput. Appl. Math. 6
# (1980) (Hairer, Nørsett & Wanner, Table II.5.2); quartic dense output of Shampine, "Some
# practical Runge-Kutta formulas", Math. Comp. 46 (1986). The error weights are the 4th-order
# weights minus the 5th-order ones, subtracted in floating point.
_DP5_B = np.array([35 / 384, 0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84])
_DP5_B_HAT = np.array(
    [5179 / 57600, 0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100, 1 / 40]
)
RK45 = PolynomialPair(
    name="RK45",
    order=5,
    error_order=4,
    c=np.array([0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1]),
    a=np.array(
        [
            [0, 0, 0, 0, 0, 0],
            [1 / 5, 0, 0, 0, 0, 0],
            [3 / 40, 9 / 40, 0, 0, 0, 0],
            [44 / 45, -56 / 15, 32 / 9, 0, 0, 0],
            [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0, 0],
            [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656, 0],
        ]
    ),
    b=_DP5_B,
    e=_DP5_B_HAT - np.append(_DP5_B, 0.0),
    p=np.array(
        [
            [1, -8048581381 / 2820520608, 8663915743 / 2820520608, -12715105075 / 11282082432],
            [0, 0, 0, 0],
            [
                0,
                131558114200 / 32700410799,
                -68118460800 / 10900136933,
                87487479700 / 32700410799,
            ],
            [
                0,
                -1754552775 / 470086768,
                14199869525 / 1410260304,
                -10690763975 / 1880347072,
            ],
            [
                0,
                127303824393 / 49829197408,
                -318862633887 / 49829197408,
                701980252875 / 199316789632,
            ],
            [0, -282668133 / 205662961, 2019193451 / 616988883, -1453857185 / 822651844],
            [0, 40617522 / 29380423, -110615467 / 29380423, 69997945 / 29380423],
        ]
    ),
)


def _from_rows(rows: Mapping[int, Mapping[int, float]], shape: tuple[int, int]) -> NDArray:
    """A dense array from its nonzero entries, {row: {column: value}}."""
    array = np.zeros(shape)
    for row, entries in rows.items():
        for column, value in entries.items():
            array[row, column] = value
    return array


# Dormand–Prince 8(5,3): the coefficients of Hairer's DOP853 code (Hairer, Nørsett & Wanner,
# Sec. II.10; http://www.unige.ch/~hairer/software.html). Stages 0–11 make the step, stage 12
# is f(t + h, y_new) (row 12 of A holds the weights b), stages 13–15 serve the dense output.
_DOP853_C = np.array(
    [
        0.0,
        0.526001519587677318785587544488e-01,
        0.789002279381515978178381316732e-01,
        0.118350341907227396726757197510,
        0.281649658092772603273242802490,
        0.333333333333333333333333333333,
        0.25,
        0.307692307692307692307692307692,
        0.651282051282051282051282051282,
        0.6,
        0.857142857142857142857142857142,
        1.0,
        1.0,
        0.1,
        0.2,
        0.777777777777777777777777777778,
    ]
)
_DOP853_A = _from_rows(
    {
        1: {0: 5.26001519587677318785587544488e-2},
        2: {0: 1.97250569845378994544595329183e-2, 1: 5.91751709536136983633785987549e-2},
        3: {0: 2.95875854768068491816892993775e-2, 2: 8.87627564304205475450678981324e-2},
        4: {
            0: 2.41365134159266685502369798665e-1,
            2: -8.84549479328286085344864962717e-1,
            3: 9.24834003261792003115737966543e-1,
        },
        5: {
            0: 3.7037037037037037037037037037e-2,
            3: 1.70828608729473871279604482173e-1,
            4: 1.25467687566822425016691814123e-1,
        },
        6: {
            0: 3.7109375e-2,
            3: 1.70252211019544039314978060272e-1,
            4: 6.02165389804559606850219397283e-2,
            5: -1.7578125e-2,
        },
        7: {
            0: 3.70920001185047927108779319836e-2,
            3: 1.70383925712239993810214054705e-1,
            4: 1.07262030446373284651809199168e-1,
            5: -1.53194377486244017527936158236e-2,
            6: 8.27378916381402288758473766002e-3,
        },
        8: {
            0: 6.24110958716075717114429577812e-1,
            3: -3.36089262944694129406857109825,
            4: -8.68219346841726006818189891453e-1,
            5: 2.75920996994467083049415600797e1,
            6: 2.01540675504778934086186788979e1,
            7: -4.34898841810699588477366255144e1,
        },
        9: {
            0: 4.77662536438264365890433908527e-1,
            3: -2.48811461997166764192642586468,
            4: -5.90290826836842996371446475743e-1,
            5: 2.12300514481811942347288949897e1,
            6: 1.52792336328824235832596922938e1,
            7: -3.32882109689848629194453265587e1,
            8: -2.03312017085086261358222928593e-2,
        },
        10: {
            0: -9.3714243008598732571704021658e-1,
            3: 5.18637242884406370830023853209,
            4: 1.09143734899672957818500254654,
            5: -8.14978701074692612513997267357,
            6: -1.85200656599969598641566180701e1,
            7: 2.27394870993505042818970056734e1,
            8: 2.49360555267965238987089396762,
            9: -3.0467644718982195003823669022,
        },
        11: {
            0: 2.27331014751653820792359768449,
            3: -1.05344954667372501984066689879e1,
            4: -2.00087205822486249909675718444,
            5: -1.79589318631187989172765950534e1,
            6: 2.79488845294199600508499808837e1,
            7: -2.85899827713502369474065508674,
            8: -8.87285693353062954433549289258,
            9: 1.23605671757943030647266201528e1,
            10: 6.43392746015763530355970484046e-1,
        },
        12: {
            0: 5.42937341165687622380535766363e-2,
            5: 4.45031289275240888144113950566,
            6: 1.89151789931450038304281599044,
            7: -5.8012039600105847814672114227,
            8: 3.1116436695781989440891606237e-1,
            9: -1.52160949662516078556178806805e-1,
            10: 2.01365400804030348374776537501e-1,
            11: 4.47106157277725905176885569043e-2,
        },
        13: {
            0: 5.61675022830479523392909219681e-2,
            6: 2.53500210216624811088794765333e-1,
            7: -2.46239037470802489917441475441e-1,
            8: -1.24191423263816360469010140626e-1,
            9: 1.5329179827876569731206322685e-1,
            10: 8.20105229563468988491666602057e-3,
            11: 7.56789766054569976138603589584e-3,
            12: -8.298e-3,
        },
        14: {
            0: 3.18346481635021405060768473261e-2,
            5: 2.83009096723667755288322961402e-2,
            6: 5.35419883074385676223797384372e-2,
            7: -5.49237485713909884646569340306e-2,
            10: -1.08347328697249322858509316994e-4,
            11: 3.82571090835658412954920192323e-4,
            12: -3.40465008687404560802977114492e-4,
            13: 1.41312443674632500278074618366e-1,
        },
        15: {
            0: -4.28896301583791923408573538692e-1,
            5: -4.69762141536116384314449447206,
            6: 7.68342119606259904184240953878,
            7: 4.06898981839711007970213554331,
            8: 3.56727187455281109270669543021e-1,
            12: -1.39902416515901462129418009734e-3,
            13: 2.9475147891527723389556272149,
            14: -9.15095847217987001081870187138,
        },
    },
    (16, 16),
)
# The 3rd-order estimate is b minus the 3rd-order weights (nonzero at stages 0, 8, 11).
_DOP853_B3 = _from_rows(
    {
        0: {
            0: 0.244094488188976377952755905512,
            8: 0.733846688281611857341361741547,
            11: 0.220588235294117647058823529412e-1,
        }
    },
    (1, 13),
)[0]
_DOP853_E5 = _from_rows(
    {
        0: {
            0: 0.1312004499419488073250102996e-1,
            5: -0.1225156446376204440720569753e1,
            6: -0.4957589496572501915214079952,
            7: 0.1664377182454986536961530415e1,
            8: -0.3503288487499736816886487290,
            9: 0.3341791187130174790297318841,
            10: 0.8192320648511571246570742613e-1,
            11: -0.2235530786388629525884427845e-1,
        }
    },
    (1, 13),
)[0]
_DOP853_D = _from_rows(
    {
        0: {
            0: -0.84289382761090128651353491142e1,
            5: 0.56671495351937776962531783590,
            6: -0.30689499459498916912797304727e1,
            7: 0.23846676565120698287728149680e1,
            8: 0.21170345824450282767155149946e1,
            9: -0.87139158377797299206789907490,
            10: 0.22404374302607882758541771650e1,
            11: 0.63157877876946881815570249290,
            12: -0.88990336451333310820698117400e-1,
            13: 0.18148505520854727256656404962e2,
            14: -0.91946323924783554000451984436e1,
            15: -0.44360363875948939664310572000e1,
        },
        1: {
            0: 0.10427508642579134603413151009e2,
            5: 0.24228349177525818288430175319e3,
            6: 0.16520045171727028198505394887e3,
            7: -0.37454675472269020279518312152e3,
            8: -0.22113666853125306036270938578e2,
            9: 0.77334326684722638389603898808e1,
            10: -0.30674084731089398182061213626e2,
            11: -0.93321305264302278729567221706e1,
            12: 0.15697238121770843886131091075e2,
            13: -0.31139403219565177677282850411e2,
            14: -0.93529243588444783865713862664e1,
            15: 0.35816841486394083752465898540e2,
        },
        2: {
            0: 0.19985053242002433820987653617e2,
            5: -0.38703730874935176555105901742e3,
            6: -0.18917813819516756882830838328e3,
            7: 0.52780815920542364900561016686e3,
            8: -0.11573902539959630126141871134e2,
            9: 0.68812326946963000169666922661e1,
            10: -0.10006050966910838403183860980e1,
            11: 0.77771377980534432092869265740,
            12: -0.27782057523535084065932004339e1,
            13: -0.60196695231264120758267380846e2,
            14: 0.84320405506677161018159903784e2,
            15: 0.11992291136182789328035130030e2,
        },
        3: {
            0: -0.25693933462703749003312586129e2,
            5: -0.15418974869023643374053993627e3,
            6: -0.23152937917604549567536039109e3,
            7: 0.35763911791061412378285349910e3,
            8: 0.93405324183624310003907691704e2,
            9: -0.37458323136451633156875139351e2,
            10: 0.10409964950896230045147246184e3,
            11: 0.29840293426660503123344363579e2,
            12: -0.43533456590011143754432175058e2,
            13: 0.96324553959188282948394950600e2,
            14: -0.39177261675615439165231486172e2,
            15: -0.14972683625798562581422125276e3,
        },
    },
    (4, 16),
)
DOP853 = DOP853Pair(
    name="DOP853",
    order=8,
    error_order=7,
    c=_DOP853_C[:12],
    a=_DOP853_A[:12, :12],
    b=_DOP853_A[12, :12],
    e=_DOP853_E5,
    e3=np.append(_DOP853_A[12, :12], 0.0) - _DOP853_B3,
    c_extra=_DOP853_C[13:],
    a_extra=_DOP853_A[13:],
    d=_DOP853_D,
)

#: The explicit pairs by name.
PAIRS: Mapping[str, EmbeddedPair] = {pair.name: pair for pair in (RK23, RK45, DOP853)}


# =========================================================================== stepping


def rk_step(
    pair: EmbeddedPair,
    fun: Rhs,
    t: float,
    y: NDArray[np.float64],
    f: NDArray[np.float64],
    h: float,
    stages: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """One step of ``pair`` from ``(t, y)``.

    Parameters
    ----------
    pair:
        The method.
    fun:
        ``fun(t, y) -> dy/dt`` on (n,) vectors.
    t, y:
        Start of the step; ``y`` of shape (n,).
    f:
        ``fun(t, y)``, (n,).
    h:
        Step size.
    stages:
        :meth:`EmbeddedPair.stage_storage`; rows 0 to s are overwritten with the stage
        derivatives, row s being ``fun(t + h, y_new)``.

    Returns
    -------
    tuple[NDArray, NDArray]
        ``y_new`` and ``fun(t + h, y_new)``, each (n,).
    """
    K = stages[: pair.stages + 1]
    K[0] = f
    for s in range(1, pair.stages):
        dy = np.dot(K[:s].T, pair.a[s, :s]) * h
        K[s] = fun(t + pair.c[s] * h, y + dy)
    y_new = y + h * np.dot(K[:-1].T, pair.b)
    f_new = fun(t + h, y_new)
    K[-1] = f_new
    return y_new, f_new


def rms(x: NDArray[np.float64]) -> float:
    """Root mean square of all entries of ``x``."""
    return float(np.linalg.norm(x) / x.size**0.5)


def node_rms(x: NDArray[np.float64], n_nodes: int) -> float:
    """Largest per-node root mean square of a raveled (d, B) array ``x``, B = ``n_nodes``."""
    return float(np.max(np.sqrt(np.mean(x.reshape(-1, n_nodes) ** 2, axis=0))))


def step_factor(norm: float, error_order: int) -> float:
    """Factor for the next step size after an error ``norm`` (1 = the tolerance).

    ``SAFETY·norm^(-1/(error_order + 1))``, kept within ``[MIN_FACTOR, MAX_FACTOR]``.
    """
    if norm == 0.0:
        return MAX_FACTOR
    return min(MAX_FACTOR, max(MIN_FACTOR, SAFETY * norm ** (-1 / (error_order + 1))))


def initial_step(
    fun: Rhs,
    t: float,
    y: NDArray[np.float64],
    f: NDArray[np.float64],
    span: float,
    error_order: int,
    rtol: float,
    atol: float | NDArray[np.float64],
    norm: Callable[[NDArray[np.float64]], float],
) -> float:
    """Starting step size (Hairer, Nørsett & Wanner, Solving ODEs I, Sec. II.4).

    From the sizes of ``y``, ``f = fun(t, y)`` and a difference estimate of f' (one more call
    of ``fun``), each measured by ``norm`` relative to ``atol + rtol·|y|``; at most ``span``.

    Parameters
    ----------
    fun, t, y, f:
        Right-hand side, initial time, state (n,) and derivative (n,).
    span:
        Length of the integration interval.
    error_order:
        Order of the error estimate (see :class:`EmbeddedPair`).
    rtol, atol:
        Tolerances; ``atol`` scalar or (n,).
    norm:
        Norm of a scaled (n,) vector (:func:`rms` or a per-node norm).
    """
    scale = atol + np.abs(y) * rtol
    d0 = norm(y / scale)
    d1 = norm(f / scale)
    h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
    h0 = min(h0, span)
    f1 = fun(t + h0, y + h0 * f)
    d2 = norm((f1 - f) / scale) / h0
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** (1 / (error_order + 1))
    return min(100 * h0, h1, span)


def integrate(
    pair: EmbeddedPair,
    fun: Rhs,
    t0: float,
    y0: NDArray[np.float64],
    t_eval: NDArray[np.float64],
    *,
    rtol: float,
    atol: float | NDArray[np.float64],
    n_nodes: int,
) -> NDArray[np.float64]:
    """Integrate a stacked batch from ``t0`` to ``t_eval[-1]`` and sample it at ``t_eval``.

    Adaptive steps: a step is accepted when :meth:`EmbeddedPair.error_norm` with the scale
    ``atol + rtol·max(|y|, |y_new|)`` is below 1; the next step is the current one times
    :func:`step_factor`, not enlarged right after a rejection. The starting step is
    :func:`initial_step` with the RMS norm over the whole stack. Each output time is sampled
    from the dense output of the first step that reaches or passes it.

    Parameters
    ----------
    pair:
        The method.
    fun:
        ``fun(t, y) -> dy/dt`` on (n,) vectors, n = d·B.
    t0, y0:
        Initial time and state (n,).
    t_eval:
        Output times, (T,), increasing, within ``[t0, t_eval[-1]]`` and ``t_eval[-1] > t0``.
    rtol, atol:
        Tolerances; ``rtol`` at least 100 machine epsilons, ``atol`` scalar or (n,).
    n_nodes:
        B: the state vector is a raveled (d, B) array.

    Returns
    -------
    NDArray
        States at ``t_eval``, (n, T).

    Raises
    ------
    ModelError
        The step size fell below ten floating-point spacings of t.
    """
    t_end = float(t_eval[-1])
    t, y = float(t0), y0
    f = fun(t, y)
    h_abs = initial_step(fun, t, y, f, t_end - t, pair.error_order, rtol, atol, rms)
    stages = pair.stage_storage(y.size)
    samples = []
    sampled = 0
    while t < t_end:
        min_step = 10 * np.abs(np.nextafter(t, np.inf) - t)
        h_abs = max(h_abs, min_step)
        rejected = False
        while True:
            if h_abs < min_step:
                raise ModelError(
                    f"{pair.name} integration failed near t={t:.6g}: the required step size is "
                    "below the spacing of floating-point numbers"
                )
            t_new = min(t + h_abs, t_end)
            h = t_new - t
            h_abs = abs(h)
            y_new, f_new = rk_step(pair, fun, t, y, f, h, stages)
            scale = atol + np.maximum(np.abs(y), np.abs(y_new)) * rtol
            norm = pair.error_norm(stages[: pair.stages + 1], h, scale, n_nodes)
            factor = step_factor(norm, pair.error_order)
            if norm < 1:
                h_abs *= min(1.0, factor) if rejected else factor
                break
            h_abs *= factor
            rejected = True
        t_old, y_old = t, y
        t, y, f = t_new, y_new, f_new
        reached = int(np.searchsorted(t_eval, t, side="right"))
        if reached > sampled:
            sample = pair.interpolant(fun, t_old, y_old, y, h, stages)
            samples.append(sample(t_eval[sampled:reached]))
            sampled = reached
    return np.hstack(samples)
