"""Host software for the MARG sphere.

The package has a pure core (protocol decoding, fusion, filters, mapping) that works on arrays and
packet iterators, and thin edges (serial ports, capture files, output backends, the command line).
"""

__version__ = "0.1.0"
