"""Physical parameters of the AR.Drone 2.0 as measured in the report (chapter 2, App. D, E).

Every number is transcribed exactly as the report prints it; the raw tables live in
``datasets/ardrone2/*.csv`` (see its README) and ``tests/model/test_params.py`` checks that
this module and those files agree.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, fields, replace

import numpy as np

from visloc.types import FloatArray

_TUPLE_FIELDS = ("inertia_no_hull", "inertia_hull_markers", "c_quad3", "c_quad4", "d_quad4")


@dataclass(frozen=True, kw_only=True)
class ARDrone2Params:
    """AR.Drone 2.0 (TU/e Parrot quad number 3) with its protective indoor hull.

    Attributes
    ----------
    g : float
        Gravitational acceleration, m/s^2 (report App. D nomenclature: 9.81).
    mass : float
        Complete mass including the indoor hull, kg (report Table 2.1: 0.456).
    mass_base, mass_battery, mass_indoor_hull : float
        Component masses, kg (report Table 2.1: 0.292, 0.104, 0.060).
    Ixx, Iyy, Izz : float
        Principal moments of inertia with indoor hull, kg m^2 (report Table 2.2, the means of
        the bifilar measurements of App. D: 0.0033, 0.0037, 0.0068). The body axes are the
        principal axes, ``J = diag(Ixx, Iyy, Izz)`` (report eq. 2.8).
    cog_height : float
        Height of the centre of gravity above the ground supports, m (report section 2.2.1:
        48 mm). The CoG lies in the x-y plane where the motor arms cross.
    mass_no_hull : float
        Mass used for the bifilar measurements without hull, kg (report App. D: 0.398; note
        that Table 2.1 gives base + battery = 0.396 kg).
    inertia_no_hull : tuple of 3 float
        ``(Ixx, Iyy, Izz)`` without hull, kg m^2 (report App. D: 0.0023, 0.0026, 0.0045).
    mass_hull_markers : float
        Mass with indoor hull and the tracking markers of Figure G.2, kg (report App. D: 0.502).
    inertia_hull_markers : tuple of 3 float
        ``(Ixx, Iyy, Izz)`` with hull and markers, kg m^2 (report App. D: 0.0057, 0.0058, 0.0117).
    c_quad3, c_quad4 : tuple of 4 float
        Thrust coefficients ``c_i`` of motors 1-4 of quadrotors 3 and 4, N/%^2 (report Table E.1).
    d_quad4 : tuple of 4 float
        Torque coefficients ``d_i`` of motors 1-4 of quadrotor 4, N m/%^2 (report Table E.1;
        the report prints none for quadrotor 3).
    c_mean, c_std : float
        Mean and standard deviation of the eight ``c_i``, N/%^2 (Tables 2.3 and E.1).
    d_mean, d_std : float
        Mean and standard deviation of the four ``d_i``, N m/%^2 (Tables 2.3 and E.1).
    k, k_std : float
        Shared pwm shift of eqs. (2.15)-(2.16) and its standard deviation, % (Table 2.3: 25.19, 0).
    arm : float or None
        Distance ``d`` of eq. (2.12) from a motor centre to the body x or y axis (not the
        diagonal distance), m. **The report does not print a value**, so it is ``None`` here;
        set it with ``dataclasses.replace(ARDRONE2, arm=...)`` or pass ``arm=`` to
        :func:`visloc.model.mixer_matrix` before using the mixer.
    """

    g: float = 9.81  # report App. D nomenclature
    mass: float = 0.456  # report Table 2.1
    mass_base: float = 0.292  # report Table 2.1
    mass_battery: float = 0.104  # report Table 2.1
    mass_indoor_hull: float = 0.060  # report Table 2.1
    Ixx: float = 0.0033  # report Table 2.2 / App. D mean
    Iyy: float = 0.0037  # report Table 2.2 / App. D mean
    Izz: float = 0.0068  # report Table 2.2 / App. D mean
    cog_height: float = 0.048  # report section 2.2.1
    mass_no_hull: float = 0.398  # report App. D, "No hull"
    inertia_no_hull: tuple[float, float, float] = (0.0023, 0.0026, 0.0045)  # App. D
    mass_hull_markers: float = 0.502  # report App. D, "hull + markers"
    inertia_hull_markers: tuple[float, float, float] = (0.0057, 0.0058, 0.0117)  # App. D
    c_quad3: tuple[float, float, float, float] = (0.1387e-3, 0.1412e-3, 0.1172e-3, 0.1202e-3)
    c_quad4: tuple[float, float, float, float] = (0.1469e-3, 0.1473e-3, 0.1143e-3, 0.1283e-3)
    d_quad4: tuple[float, float, float, float] = (0.9550e-5, 0.9574e-5, 0.7427e-5, 0.8337e-5)
    c_mean: float = 0.1318e-3  # report Table 2.3 / E.1
    c_std: float = 1.349e-5  # report Table 2.3 / E.1
    d_mean: float = 0.8722e-5  # report Table 2.3 / E.1
    d_std: float = 1.039e-6  # report Table 2.3 / E.1
    k: float = 25.19  # report Table 2.3 / E.1
    k_std: float = 0.0  # report Table 2.3 / E.1
    arm: float | None = None  # eq. (2.12) "d": not printed in the report

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "arm" and value is None:
                continue
            values = value if f.name in _TUPLE_FIELDS else (value,)
            expected = 3 if f.name.startswith("inertia") else 4
            if f.name in _TUPLE_FIELDS and (not isinstance(value, tuple) or len(value) != expected):
                raise TypeError(f"{f.name}: expected a tuple of {expected} floats, got {value!r}")
            for v in values:
                if isinstance(v, bool) or not isinstance(v, numbers.Real):
                    raise TypeError(f"{f.name}: expected a real number, got {type(v).__name__}")
                if not math.isfinite(v):
                    raise ValueError(f"{f.name}: expected a finite value, got {v!r}")
                if f.name in ("k", "k_std", "c_std", "d_std"):
                    if f.name != "k" and v < 0:
                        raise ValueError(f"{f.name}: expected >= 0, got {v!r}")
                elif v <= 0:
                    raise ValueError(f"{f.name}: expected > 0, got {v!r}")

    @property
    def J(self) -> FloatArray:
        """Inertia matrix ``diag(Ixx, Iyy, Izz)`` (3, 3), kg m^2 (report eq. 2.8)."""
        return np.diag([self.Ixx, self.Iyy, self.Izz]).astype(float)

    @property
    def c_motors(self) -> FloatArray:
        """Nominal thrust coefficient of motors 1-4 (4,), N/%^2: the mean ``c_mean`` for each."""
        return np.full(4, self.c_mean)

    @property
    def d_motors(self) -> FloatArray:
        """Nominal torque coefficient of motors 1-4 (4,), N m/%^2: the mean ``d_mean`` for each."""
        return np.full(4, self.d_mean)

    @property
    def c_all(self) -> FloatArray:
        """The eight measured thrust coefficients (8,), N/%^2: quads 3 then 4, motors 1-4 each."""
        return np.array(self.c_quad3 + self.c_quad4)

    def without_hull(self) -> ARDrone2Params:
        """The same drone without its indoor hull (App. D "No hull": m = 0.398 kg).

        Returns
        -------
        ARDrone2Params
            A copy with ``mass = mass_no_hull`` and ``Ixx, Iyy, Izz = inertia_no_hull``.
        """
        ixx, iyy, izz = self.inertia_no_hull
        return replace(self, mass=self.mass_no_hull, Ixx=ixx, Iyy=iyy, Izz=izz)

    def with_markers(self) -> ARDrone2Params:
        """The drone with indoor hull and the markers of Figure G.2 (App. D: m = 0.502 kg).

        Returns
        -------
        ARDrone2Params
            A copy with ``mass = mass_hull_markers`` and ``Ixx, Iyy, Izz = inertia_hull_markers``.
        """
        ixx, iyy, izz = self.inertia_hull_markers
        return replace(self, mass=self.mass_hull_markers, Ixx=ixx, Iyy=iyy, Izz=izz)


ARDRONE2 = ARDrone2Params()
"""The report's AR.Drone 2.0 with indoor hull (``arm`` unset: the report gives no value)."""


def check_params(params: object, name: str = "params") -> ARDrone2Params:
    """Check that ``params`` is an :class:`ARDrone2Params` and return it.

    Parameters
    ----------
    params : object
        The value to check.
    name : str
        The argument's name, for the error message.

    Returns
    -------
    ARDrone2Params
        ``params`` itself.

    Raises
    ------
    TypeError
        ``params`` is not an :class:`ARDrone2Params`.
    """
    if not isinstance(params, ARDrone2Params):
        raise TypeError(f"{name}: expected ARDrone2Params, got {type(params).__name__}")
    return params
