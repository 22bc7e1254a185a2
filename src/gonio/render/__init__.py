"""gonio.render"""
