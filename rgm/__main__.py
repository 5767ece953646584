import sys

from rgm.cli import main

sys.exit(main())
