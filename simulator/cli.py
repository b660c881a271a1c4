"""impctl-sim console entry (to be filled in)."""

def main() -> None:
    raise SystemExit("impctl-sim: not implemented yet")
