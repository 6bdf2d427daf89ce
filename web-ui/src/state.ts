// The DEM chosen in the terrain section, shared by the survey (terrain
// following) and the ground-route panel (costmaps are built from it).

import type { Dem } from './api';

type Listener = (dem: Dem | null) => void;

export class DemSelection {
  private dem: Dem | null = null;
  private readonly listeners: Listener[] = [];

  get current(): Dem | null {
    return this.dem;
  }

  set(dem: Dem | null): void {
    this.dem = dem;
    for (const l of this.listeners) l(dem);
  }

  onChange(listener: Listener): void {
    this.listeners.push(listener);
  }
}
