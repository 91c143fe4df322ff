from opfbench.cli import main

raise SystemExit(main())
