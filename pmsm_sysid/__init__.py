"""pmsm_sysid: online NARX identification, GFRF analysis and sim-to-real diagnosis of a PMSM."""

__version__ = "0.1.0"
