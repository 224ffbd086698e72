from ezcompanion.console import main

raise SystemExit(main())
