"""The seed's nine detection combinations (section 4.2.4), as named methods ``seed-1`` ... ``seed-9``.

Each is a base detector plus pre-processing: the single waveform of every ping, or the
average of all pings (eq. 4.33, giving one ping), with or without the zero-phase band-pass
(default band: where the template's power is within 20 dB of its peak).

=========  =========  =========  =========
method     detector   waveform   band-pass
=========  =========  =========  =========
seed-1     threshold  single     no
seed-2     threshold  averaged   no
seed-3     matched    single     no
seed-4     matched    averaged   no
seed-5     threshold  single     yes
seed-6     threshold  averaged   yes
seed-7     matched    single     yes
seed-8     matched    averaged   yes
seed-9     local      averaged   no
=========  =========  =========  =========

The seed does not say which waveform its local matched processing (9) used; it is listed
as the cheap alternative to 4 and 8, so it runs on the averaged waveform here.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class SeedCombination:
    """One of the seed's combinations.

    Attributes
    ----------
    number : int
        1..9 as numbered in the seed.
    base : str
        The base method ("threshold", "matched" or "local-matched").
    average : bool
        Average all pings first (eq. 4.33).
    bandpass : bool
        Band-pass filter first.
    """

    number: int
    base: str
    average: bool
    bandpass: bool

    @property
    def name(self) -> str:
        """Method name, "seed-<number>"."""
        return f"seed-{self.number}"

    @property
    def description(self) -> str:
        """The seed's wording, e.g. "matched filter on a band-pass filtered averaged waveform"."""
        detector = {"threshold": "simple threshold", "matched": "matched filter", "local-matched": "local matched"}[self.base]
        waveform = f"{'band-pass filtered ' if self.bandpass else ''}{'averaged' if self.average else 'single'} waveform"
        return f"{detector} on {'an' if waveform[0] in 'aeiou' else 'a'} {waveform}"


SEED_COMBINATIONS: tuple[SeedCombination, ...] = (
    SeedCombination(1, "threshold", False, False),
    SeedCombination(2, "threshold", True, False),
    SeedCombination(3, "matched", False, False),
    SeedCombination(4, "matched", True, False),
    SeedCombination(5, "threshold", False, True),
    SeedCombination(6, "threshold", True, True),
    SeedCombination(7, "matched", False, True),
    SeedCombination(8, "matched", True, True),
    SeedCombination(9, "local-matched", True, False),
)


def seed_combination(name: str) -> SeedCombination:
    """The combination called ``name`` ("seed-1" ... "seed-9"); KeyError if none."""
    for combination in SEED_COMBINATIONS:
        if combination.name == name:
            return combination
    raise KeyError(name)
