"""Waveform synthesis: traced paths -> three-channel, digitised pings (``acoustisim.synthesis``).

- :mod:`transducer`: pulse spectrum and band, fast piston-directivity table.
- :mod:`synthesiser`: paths -> band-limited pressure at the receivers (exact fractional delays,
  per-bin directivity and absorption), no Python loop over rows.
- :mod:`row_kernels`: its compiled loops over rows (numba, imported on first use).
- :mod:`chain`: :class:`ReceiverChain` (sensitivity, gains, band-pass, main bang, TVG, noise
  settings, ADC range).
- :mod:`noise`: thermal (Mellen) and electrical noise spectra.
- :mod:`adc`: rounding, clipping.
- :mod:`pings`: :class:`PingSynthesiser`, the template and the per-ping rendering.
- :mod:`ping_loops`: its compiled per-bin and per-sample loops (noise scaling, TVG + ADC).
"""

from acoustisim.synthesis.chain import InterferenceLine, ReceiverChain, TimeVaryingGain
from acoustisim.synthesis.pings import Pings, PingSynthesiser

__all__ = ["InterferenceLine", "Pings", "PingSynthesiser", "ReceiverChain", "TimeVaryingGain"]
