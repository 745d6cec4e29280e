"""odocan host: the tools a person runs (CLI, decoding, float64 reference, reports, MQTT)."""
