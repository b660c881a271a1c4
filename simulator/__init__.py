"""Kronoterm heat-pump Modbus simulator backed by the 5R1C model (comes with the link issue)."""
