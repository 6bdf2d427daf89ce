import type { CustomCamera, SurveyFormValues } from '../src/survey-form';

/** The Phantom 4 Pro's sensor, as the custom camera fields hold it. */
export const P4: CustomCamera = { sensor_width_mm: 13.2, sensor_height_mm: 8.8, focal_length_mm: 8.8, image_width_px: 5472, image_height_px: 3648, orientation: 'landscape' };

/** Survey form values as a test starts from: no area, the API's defaults written out (so a changed default shows in the tests), overridden by `over`. */
export function formValues(over: Partial<SurveyFormValues> = {}): SurveyFormValues {
  return {
    name: '',
    roi: null,
    noFlyZones: [],
    demId: null,
    allowPartialDem: false,
    camera: 'dji_phantom4_pro',
    customCamera: P4,
    heightMode: 'altitude',
    altitudeM: 60,
    gsdCmPx: 1.5,
    frontOverlapPct: 80,
    sideOverlapPct: 70,
    sliceAngle: 'auto',
    speedMS: 10,
    nfzClearanceM: 5,
    altitudeFrame: 'relative',
    assignment: 'balanced',
    batteryMin: NaN,
    uavs: [],
    rallyPoints: [],
    extra: {},
    ...over,
  };
}
