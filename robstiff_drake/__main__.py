import sys

from robstiff_drake.commands.main import main

sys.exit(main())
