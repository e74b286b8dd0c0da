import sys

from iat.cli.commands import main

sys.exit(main())
