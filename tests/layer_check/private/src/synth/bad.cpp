// Fixture for the layer check's own test: a layer must not include another layer's private header.
#include "io/crc32.hpp"
