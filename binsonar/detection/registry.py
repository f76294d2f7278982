"""Every method name ``detect`` accepts, and what it stands for.

A name is a base method (``methods.BASE_METHOD_OBJECTS``: "threshold", "matched", ...) or one
of the seed's nine combinations ("seed-1" ... "seed-9", ``seed.SEED_COMBINATIONS``): a base
method with its pre-processing (the pings averaged, the template's band-pass). ``lookup(name)``
gives the ``RegisteredMethod``; ``METHODS`` lists the names.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import Mapping

from binsonar.detection.methods import BASE_BY_NAME, BASE_METHOD_OBJECTS, DetectionMethod
from binsonar.detection.seed import SEED_COMBINATIONS
from binsonar.recording import RecordingError


@dataclass(frozen=True)
class RegisteredMethod:
    """A method name and what it runs.

    Attributes
    ----------
    name : str
        The name ``detect`` accepts.
    method : DetectionMethod
        The base method that detects.
    average : bool
        Average the pings first (eq. 4.33), unless the caller says otherwise.
    bandpass_template : bool
        Band-pass over the template's band first, unless the caller gives a band.
    description : str
        One line for listings.
    """

    name: str
    method: DetectionMethod
    average: bool
    bandpass_template: bool
    description: str


REGISTRY: Mapping[str, RegisteredMethod] = MappingProxyType({
    **{m.name: RegisteredMethod(m.name, m, False, False, m.summary) for m in BASE_METHOD_OBJECTS},
    **{c.name: RegisteredMethod(c.name, BASE_BY_NAME[c.base], c.average, c.bandpass, c.description)
       for c in SEED_COMBINATIONS},
})
"""Every accepted name, base methods first, then the seed's combinations in their order."""

BASE_METHODS: tuple[str, ...] = tuple(m.name for m in BASE_METHOD_OBJECTS)
METHODS: tuple[str, ...] = tuple(REGISTRY)


def lookup(name: str) -> RegisteredMethod:
    """The registered method called ``name``.

    Raises
    ------
    RecordingError
        An unknown name (the message lists the known ones).
    """
    try:
        return REGISTRY[name]
    except (KeyError, TypeError):
        raise RecordingError(f"unknown detection method {name!r}; choose one of: {', '.join(METHODS)}") from None
