// Fixture for the layer check's own test: a public header must not include a private header,
// not even one of its own layer (an installed tree has no src/).
#include "io/crc32.hpp"
