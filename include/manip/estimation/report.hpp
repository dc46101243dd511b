#pragma once
// Presenting a Report, one header per output (report/): the Table-1 text,
// JSON (layout in docs/estimator.md), CSV, per-trial signal export, and
// figures/report drawn by python/manipplot (render.hpp). The settings and their YAML are in settings.hpp.
#include "manip/estimation/report/csv.hpp"
#include "manip/estimation/report/json.hpp"
#include "manip/estimation/report/render.hpp"
#include "manip/estimation/report/signals.hpp"
#include "manip/estimation/report/text.hpp"
#include "manip/estimation/settings.hpp"
