#!/usr/bin/env python3
"""Draw the flight path and the last OCP plan of a recorded bag to a PNG.

    scripts/in_env.sh python scripts/bag_to_png.py BAG OUT.png [--path-index -1] [--title T]

The bag needs lander/path (and ocp/plan for the plan), which `pd_record` records by default.
The work is done by `pd_bringup.bag_plot` (importable, tested).
"""

from __future__ import annotations

import sys

from pd_bringup.bag_plot import main

if __name__ == "__main__":
    sys.exit(main())
