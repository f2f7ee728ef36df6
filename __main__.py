from mdaug.cli import main

raise SystemExit(main())
