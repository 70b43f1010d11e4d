#pragma once
// placeholder: being written (association, Umeyama alignment, ATE, RPE)
