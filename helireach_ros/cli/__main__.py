"""``python -m helireach_ros.cli`` runs the ``helireach`` command."""

import sys

from helireach_ros.cli.main import main

sys.exit(main())
