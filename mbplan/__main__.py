import sys

from mbplan.cli import main

sys.exit(main())
