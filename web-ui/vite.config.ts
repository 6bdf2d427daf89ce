import { defineConfig } from 'vitest/config';

// `npm run dev` proxies the API to a running `terraplan serve` (TERRAPLAN_URL,
// default http://127.0.0.1:8080) so the page and the API share one origin.
const api = process.env.TERRAPLAN_URL ?? 'http://127.0.0.1:8080';

export default defineConfig({
  base: '/',
  server: {
    proxy: {
      '/api': { target: api, changeOrigin: true },
      '/healthz': { target: api, changeOrigin: true },
    },
  },
  build: {
    outDir: 'dist',
    emptyOutDir: true,
    sourcemap: false,
    chunkSizeWarningLimit: 1200,
  },
  test: {
    include: ['test/**/*.test.ts'],
    environment: 'node',
  },
});
