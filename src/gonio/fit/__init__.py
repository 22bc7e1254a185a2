"""gonio.fit"""
