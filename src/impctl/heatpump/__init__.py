"""Kronoterm heat pump over Modbus: register map, decoding, safe client."""
