"""`python -m offroad_path.postprocess`."""

from offroad_path.postprocess import main

main()
