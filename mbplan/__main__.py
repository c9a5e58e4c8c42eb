import sys

from mbplan.cli.main import main

sys.exit(main())
