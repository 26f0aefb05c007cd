"""2D pre-detection with a bank of part-configuration detectors (paper Sec. 3.4, 5.2)."""

from wirescene.predetect.bank import (
    DEFAULT_BANK_PATH,
    DetectorBank,
    cluster_activations,
    detect_cars,
    load_default_bank,
)

__all__ = ["DEFAULT_BANK_PATH", "DetectorBank", "cluster_activations", "detect_cars", "load_default_bank"]
