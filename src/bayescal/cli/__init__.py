"""The command line: ``bayescal COMMAND`` (also ``python -m bayescal COMMAND``).

* :mod:`bayescal.cli.main` -- the click commands (``main`` is the group);
* :mod:`bayescal.cli.joint` -- ``bayescal joint`` (added to the group here);
* :mod:`bayescal.cli.progress` -- all terminal text: summaries, tables, progress bars;
* :mod:`bayescal.cli.reference` -- the generated command-line reference (``docs/cli.md``).
"""

from bayescal.cli.joint import joint
from bayescal.cli.main import main

main.add_command(joint)

__all__ = ["main"]
