#pragma once
// A lower layer that includes a higher one: check_layers.py must refuse it.
#include "high/y.h"
