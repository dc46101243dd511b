import sys

from manipdisplay.app import main

sys.exit(main())
