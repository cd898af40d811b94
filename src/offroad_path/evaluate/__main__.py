"""`python -m offroad_path.evaluate`."""

from offroad_path.evaluate import main

main()
