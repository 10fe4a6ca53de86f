import sys

from fmu_src.fmi.conformance.cli import main

sys.exit(main())
