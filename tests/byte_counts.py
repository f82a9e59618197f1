"""Byte counts the tests state their expectations in, named rather than written as bare numbers."""

KIB = 1 << 10
MIB = 1 << 20
FLOAT32_BYTES = 4
TRIANGLE_FLOAT32_BYTES = 3 * 3 * FLOAT32_BYTES  # one triangle as a (3, 3) float32 array
