from ezcompanion.cli import main

raise SystemExit(main())
