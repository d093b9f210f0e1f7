import sys

from robstiff_drake.cli import main

sys.exit(main())
