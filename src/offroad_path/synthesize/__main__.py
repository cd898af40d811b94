"""`python -m offroad_path.synthesize`."""

from offroad_path.synthesize import main

main()
