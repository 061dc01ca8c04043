"""Live scanners: the wire protocols of the scanners MAST reads as they stream."""
