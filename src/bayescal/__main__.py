"""``python -m bayescal COMMAND``: the command line, as the ``bayescal`` script runs it."""

from bayescal.cli import main

if __name__ == "__main__":
    main(prog_name="bayescal")
