import sys

# before anything else is imported: an interrupt during start-up is then one line, not a traceback
from gonio import interrupts

interrupts.install()

from gonio.cli import main  # noqa: E402

sys.exit(main())
