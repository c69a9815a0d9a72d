from gdlearn.cli import main

raise SystemExit(main())
