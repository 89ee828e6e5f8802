#include "wmo/collision/narrowphase.h"
