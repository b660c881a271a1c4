"""Commands for the gateway's operator: the daemon itself, manual nights (trigger, restore), what
it is doing (status, nights), export, check-config. Light: no torch, scikit-learn or pandas at
import time, so the daemon's process stays small."""
