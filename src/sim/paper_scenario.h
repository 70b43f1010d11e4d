#pragma once
// placeholder: being written (the paper's §8.1 synthetic world)
