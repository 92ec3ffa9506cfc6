from scanplan.cli import app

app()
