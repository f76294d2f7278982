"""binsonar: detection and localisation for the binaural sonar, on real-format recordings.

It never imports the simulator (``acoustisim``) or ``scenes``: simulated pings reach it
through the same recording file and arrays that the hardware produces. Importing it stays
light (numpy only); submodules load scipy, h5py and friends when used.
"""

__version__ = "0.1.0"
