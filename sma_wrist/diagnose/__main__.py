import sys

from sma_wrist.diagnose import main

sys.exit(main())
