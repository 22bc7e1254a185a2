"""gonio.acquire"""
