from raingauge.cli import main

raise SystemExit(main())
