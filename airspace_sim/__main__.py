import sys

from airspace_sim.cli import main

sys.exit(main())
