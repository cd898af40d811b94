"""`python -m offroad_path.ingest`."""

from offroad_path.ingest import main

main()
